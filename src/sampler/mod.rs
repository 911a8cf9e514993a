//! Shrunk-occluder point sampling (the fine-foliage culler's raster work): the occluders as
//! convex planar polygons with a BVH over them ([`SampleOccluders`]), and the hemicube
//! rasteriser that renders them from one sample point with every polygon's silhouette shrunk
//! for an ε-ball, then tests occludee boxes against the result ([`Hemicube`]). The per-cell
//! driver (sample points on the cell's faces, adaptive ε, certification, budget) is
//! `bake::sampling`.
//!
//! # Why it is conservative
//!
//! Let `p` be a sample point, `B` the closed ball of radius `ε` about it, `L` a convex planar
//! polygon with `dist(p, plane(L)) > ε` (polygons nearer than that are left out), and for each
//! edge `e` of `L`: `ℓ_e` its line, `r_e = dist(p, ℓ_e)` (≥ the plane distance, so `> ε`),
//! `m_e` the unit normal of the plane through `p` and `ℓ_e`, oriented toward `L`'s inside. The
//! **shrunk silhouette** of `L` from `p` is the set of directions `d` with
//! `d·m_e ≥ (ε / r_e)·|d|` for every edge (the silhouette moved inward by `asin(ε/r_e)` per
//! edge). Claim: if `d` lies in the shrunk silhouette and `q = p + t·d` lies beyond `plane(L)`,
//! then every segment from a point of `B` to `q` crosses `L`.
//!
//! *Proof.* The points `b` whose segment to `q` crosses `L` (with `q` beyond `L`) are those on
//! the other side of `plane(L)` from `q` and, for every edge, on `L`'s side of the plane
//! `Q_e` through `q` and `ℓ_e` (the shadow pyramid of `L` from `q`). `p` is such a point (its
//! ray to `q` crosses `L` inside `L`, as `d` is in the silhouette). All of `B` is on `p`'s side
//! of `plane(L)` (distance `> ε`). It remains to show `dist(p, Q_e) ≥ ε` for every edge. Look
//! along `ℓ_e` (project orthogonally onto a plane normal to it; distances to planes holding
//! `ℓ_e` are kept): `ℓ_e` becomes a point `E`, `|pE| = r_e`, the ray becomes a ray from `p`
//! making an angle `θ` with the line `pE` where `sin θ ≥ d·m_e/|d| ≥ ε/r_e` (projection keeps
//! `d·m_e` and shortens `d`). `dist(p, Q_e) = r_e·sin φ` where `φ` is the angle at `E` between
//! `p` and `q`. As a point moves along the ray from `p` to infinity this angle grows
//! monotonically from 0 to `π − θ`; `q` lies beyond the crossing `x` of `plane(L)`, so
//! `φ ∈ [φ_x, π − θ]` with `r_e·sin φ_x = dist(p, plane(L)) > ε`. `sin` is concave on
//! `[0, π]`, so on that interval it is at least `min(sin φ_x, sin θ)`, and
//! `r_e·sin φ ≥ min(dist(p, plane(L)), r_e·sin θ) ≥ ε`. ∎
//!
//! *In floating point,* the renderer takes `L`'s inside for `m_e` from the side of `e`'s plane
//! that holds `L`'s vertex centroid, and leaves `L` out when the centroid lies within rounding
//! of any edge's plane (`hemicube::ORIENT_TOL`; leaving a polygon out only uncovers): there the
//! side is not known. Three collinear points (a degenerate triangle) give all their edges one
//! plane through `p`; before this guard, when all three took the same side, the "polygon"
//! covered a half-space (`tests/sampler_proof.rs`: `collinear_polygons_hide_nothing`).
//!
//! **Rectangles instead of balls** ([`Hemicube::begin_patch`]). Only the points of a face
//! matter, and the sampler covers a face with rectangles, so the region `R` a render stands
//! for is a rectangle of the face's plane centred on `p`. The proof above only uses, per edge,
//! that the region seen along `ℓ_e` (projected onto the plane normal to it) lies within the
//! disc of radius `ε` about `p`'s projection, and that `dist(p, plane(L))` exceeds that radius.
//! For the rectangle with half sides `h_b, h_c` (axes in the face's plane) and an edge of unit
//! direction `t`, the projected corners `w − (w·t)·t` are at most
//! `ε_e = √(h_b² + h_c² − (h_b·|t_b| − h_c·|t_c|)²)` from it (the largest of the four corners
//! `w = ±h_b·e_b ± h_c·e_c`), never more than the ball's `√(h_b² + h_c²)`. So each edge is
//! shrunk by `ε_e / r_e` instead, and a polygon is left out unless its plane is farther than
//! every `ε_e`; then every segment from a point of `R` to `q` crosses `L`.
//!
//! **Supports instead of extents** (`edge_reach` in `hemicube.rs`). The disc of radius `ε_e`
//! is more than the last step needs: it needs every point of `R`'s projection on `p`'s side
//! of the line `Q_e` (through `E` at the angle `φ` from `Ep`), that is
//! `r_e·sin φ ≥ h(ν_φ)`, where `h(x) = h_b·|x_b| + h_c·|x_c|` is the rectangle's support
//! (it is centred on `p`) and `ν_φ` the unit normal of `Q_e`. In the plane normal to `ℓ_e`
//! take `m_e` (the normal of `Ep`) and `w_e = t × m_e` (along `Ep`); then
//! `ν_φ = cos φ·m_e ± sin φ·w_e` and, `h` being a symmetric norm,
//! `h(ν_φ) ≤ |cos φ|·h_n + sin φ·h_w` with `h_n = h(m_e)`, `h_w = h(w_e)`. So for
//! `r_e > h_w` the step holds whenever `sin φ·(r_e − h_w) ≥ |cos φ|·h_n`, i.e. whenever
//! `sin φ ≥ σ_e = h_n / √(h_n² + (r_e − h_w)²)`. That is the ball's condition
//! `r_e·sin φ ≥ ε` with `ε` replaced by `ε'_e = r_e·σ_e`: every step above (and the
//! depth-bounded one below) goes through with `ε'_e`, given `sin φ_x ≥ σ_e`, which holds as
//! `dist(p, plane(L))` exceeds `ε_e ≥ min(ε_e, ε'_e)`. Each edge is shrunk by the smaller of
//! `ε_e` and `ε'_e` over `r_e`. An edge whose plane through `p` is nearly the face's (seen low
//! over the face, across the line of sight) has `h_n ≈ 0`: moving the eye within the face
//! barely moves it, and it is barely shrunk. Head-on (`m_e` in the face's plane) `ε'_e` is
//! about `ε_e`. (`tests/sampler_proof.rs`, family `patch_low`, checks such edges from the
//! rectangle's corners; dropping the `h_w` term fails the check.)
//!
//! **Depth-bounded shrinks** ([`Hemicube::set_depth_bounded`], on by default). The last step
//! needs `r_e·sin φ ≥ ε` only at the angles `φ` that tested points reach. Every point a render
//! tests lies within `D` of `p`, the farthest corner of the boxes given to `begin` (a test of
//! anything reaching farther answers open), so its projection along `ℓ_e` lies within `D` of
//! `p`'s. `φ` grows with the distance along the ray, so `φ ∈ [φ_x, φ_D]`, `φ_D` the angle at
//! the ray's point `q_D` at projected distance `D`, and by concavity
//! `sin φ ≥ min(sin φ_x, sin φ_D)`. In the triangle `p, E, q_D` (angle `θ` at `p`):
//! `r_e·sin φ_D = dist(p, line E q_D) = r_e·D·sin θ / |E q_D|`, and
//! `|E q_D|² = (D − r_e)² + 4·r_e·D·sin²(θ/2)`, so for `θ ≤ π/2` (where
//! `2·sin(θ/2) ≤ √2·sin θ`) `|E q_D| ≤ |D − r_e| + √2·√(r_e·D)·sin θ`, and `r_e·sin φ_D ≥ ε`
//! whenever `sin θ ≥ (ε/r_e)·|1 − r_e/D| / (1 − √2·ε/√(r_e·D))` (a positive denominator). For
//! `θ > π/2`, `φ_D ≤ π − θ < π/2`, so `sin φ_D ≥ sin φ_x` and nothing more is needed. Each edge
//! is therefore shrunk by the smaller of `ε/r_e` and that bound (with `D` rounded up), and the
//! claim holds for every point within `D`. Leaves near the occludees (`r_e` near `D`) shrink
//! little; `bake::sampling` renders each sample point once for all its occludees (`D` their
//! farthest) and then once per band of occludee distance for those that render leaves open, so
//! that each band's `D` is tight (`tests/sampler_proof.rs`, family `depth_bounded`, checks
//! occludees just behind and among leaves).
//!
//! **Pixels.** A pixel of a hemicube view is the set of directions `(u, v, 1)` (view
//! coordinates) over a closed square of the image plane. For one edge, the directions
//! satisfying its condition meet the image plane in `{(u, v) : a·u + b·v + c ≥ s·√(u²+v²+1)}`,
//! a linear function minus a convex one: a convex set. So a pixel lies inside the shrunk
//! silhouette iff its four corners do (tested in `f32` with a margin far above the rounding
//! error). Such a pixel is covered by `L` at depth `z_max(L)`, the largest view depth of its
//! vertices rounded up: every ray in the pixel crosses `L` no deeper. A pixel keeps the nearest
//! depth of the polygons covering it, so different polygons cover different pixels: fusion.
//! Only the pixels that meet the straight-edged polygon `a·u + b·v + c ≥ s·l` (all edges,
//! `l` the least `√(u²+v²+1)` over the pixels the projection touches) are scanned: every
//! direction passing the exact tests lies in it, since there `√(u²+v²+1) ≥ l` and `s ≥ 0`.
//! When it is empty the polygon is skipped in that view (large ε shrinks most leaves to
//! nothing; skipping only ever leaves pixels uncovered, so this cannot make a test unsound).
//!
//! **Sub-pixels.** A pixel no single polygon covers is split into 8 × 8 sub-pixels. For each
//! edge the condition is relaxed to the linear `a·u + b·v + c − s·l_max ≥ margin`, where
//! `l_max` is the largest of `√(u²+v²+1)` at the pixel's corners (the root is convex, so that
//! is its maximum over the pixel, and `s ≥ 0`): wherever the linear test holds the exact one
//! does. A sub-pixel passes a linear test everywhere iff its worst corner does, so a set bit
//! means the whole sub-pixel lies inside `L`'s shrunk silhouette. The pixel keeps partial
//! **layers**, nearest first, each a mask with the largest depth of the polygons whose bits it
//! holds; a sub-pixel belongs only to its nearest layer (bits at a layer's exact depth join it,
//! bits a nearer layer holds add nothing, and a new layer takes its bits from farther ones).
//! Eight layers are kept inline and any more spill to a side table, so nothing is ever merged:
//! each sub-pixel has its own nearest depth, as on the GPU twin. When the layers up to some
//! depth together hold all 64 bits, every direction of the pixel lies in the shrunk silhouette
//! of some polygon no deeper than that, and the pixel is covered at it. Seams between leaves
//! and leaves narrower than a pixel fuse at eight times the resolution; the layers keep a near
//! leaf's bits from taking the depth of a far one drawn into the same pixel.
//!
//! **Occludees.** A box is tested with every pixel its directions can reach (the box cut to
//! the half-space `Z ≥ dist(p, box)/√3`, which holds the box's part inside the view's
//! frustum, then its exact `u`/`v` range, rounded outward to whole pixels) and its nearest view
//! depth there; it is hidden in a view when every such pixel holds a depth strictly nearer.
//! Then every point `q` of the box seen through that view lies beyond a polygon whose shrunk
//! silhouette holds the direction of `q`, and the claim hides `q` from all of `B`.
//!
//! **Occludees at sub-pixels.** A pixel that no depth covers nearer than the box still hides
//! the box's part in it when every sub-pixel that part can reach (the box's unrounded `u`/`v`
//! bounds, rounded outward to whole sub-pixels) is set in the union of the pixel's layers
//! nearer than the box: each such direction lies in the shrunk silhouette of a polygon no
//! deeper.
//!
//! **Occludee triangles** ([`Hemicube::test_triangle`]). An object whose box and pieces stay
//! open is tested triangle by triangle, each with its own part in each pixel instead of its
//! box's rectangle. Per view, the triangle is clipped to the view's frustum, then to each
//! pixel row's and each pixel's pyramid of directions, every clipping plane's slope widened
//! by 1e-9 so that each clipped polygon holds the triangle's part there despite rounding (a
//! point of the triangle in the closed pyramid passes every widened test). The pixel must
//! hold a depth strictly nearer than the clipped part's nearest view depth (less a relative
//! 1e-9), or its layers nearer than that must hold every sub-pixel of the part's `u`/`v`
//! bounds. Then each point of the triangle seen through the pixel lies beyond a polygon whose
//! shrunk silhouette holds its direction, as for boxes. On the coarse forest, a triangle's box
//! reaches pixels around the leaf where only farther leaves show; this test does not.
//!
//! **Cards** ([`SampleCard`]). A textured alpha-tested card triangle is drawn like a polygon,
//! but a pixel inside its shrunk silhouette is covered only when the texture is surely opaque
//! (`scene::alpha::Coverage`: at every trusted mip level) over the pixel's texel footprint,
//! widened for the ball (`footprint_opaque` in `hemicube.rs` gives the bound). The claim above
//! makes every segment from the ball cross the triangle; the footprint puts the crossing on a
//! surely opaque texel, where every renderer draws the card. Card triangles get no sub-pixel
//! masks.
//!
//! **Tucked edges** ([`Hemicube::set_tuck`]; `bake --sampling-tuck`, off by default). Call a
//! drawn depth *sound* when, for every direction `d` of its pixel (or sub-pixel) and every
//! point `x` along `d` beyond it within `D` of `p`, every segment from the region `R` (ball
//! or rectangle) to `x` crosses some polygon: everything above shows that each depth drawn
//! with every edge shrunk is sound. With the tuck pass, before the traversal draws a polygon
//! `L` it finds `L`'s *tucked* edges: edges lying wholly on the outer side of the face's
//! plane whose every point lies beyond a depth drawn so far (`segment_hidden`, an occludee
//! test of the edge as a segment). It draws `L` with those edges unshrunk (the other edges
//! keep their shrink; `L` is still left out when its plane is within `ε`), at its
//! farthest depth as before. Claim: every depth this draws is sound too.
//!
//! *Proof.* Let `d` be a direction of the partly shrunk silhouette, `q` beyond `L` along `d`
//! within `D`, `b` a point of `R` and `σ` the segment from `q` to `b`. `b` is on `p`'s side
//! of `plane(L)` and `q` beyond it, so `σ` crosses the plane at one point `x_L`; if `x_L ∈ L`
//! we are done. Otherwise look at the directions from `p` of the points of `σ` from `q` to
//! `x_L`: an arc of a great circle from `d` to the direction of `x_L`, which is outside the
//! cone of `L` from `p` (its ray meets `plane(L)` only at `x_L`). For each shrunk edge the
//! claim's proof puts all of `R` on `L`'s side of the plane through `q` and the edge's line,
//! so `x_L` is on the inner side of that edge; `d` is too, so the whole arc stays inside the
//! shrunk edges' half-spaces and leaves `L`'s cone through a tucked edge `e`, at the direction
//! of a point `z` of `e`. The point `y` of `σ` with that direction lies beyond `plane(L)`
//! (between `q` and `x_L`), so beyond `z` along the ray. `z` lies beyond a sound depth, so
//! `y` does, and `|y − p| ≤ max(|q − p|, |b − p|) ≤ D`: every segment from `R` to `y`
//! crosses a polygon, and the one from `b` is part of `σ`. ∎ By induction over the order of
//! drawing, every depth drawn is sound, so each polygon may rely on what any earlier one drew,
//! tucked or not. Edges reaching behind the face's
//! plane are never tucked: the views test only its outer side, and `z` may be anywhere on
//! `e`. `segment_hidden` is outer-conservative as the triangle test is (pieces between the
//! segment's crossings of pixel boundaries, bounds widened, depths strictly nearer). Cards
//! are never tucked. `tests/sampler_proof.rs` runs every family with the pass.
//!
//! **The hemisphere.** A sample point lies on a face `F` of the cell with outward normal `n`;
//! the five views (front, and the halves `v ≥ 0` of the four side views, `v` along `n`) cover
//! every direction `d` with `d·n ≥ 0`, and a box is tested only with its part on the outer side
//! of `F`'s plane. `bake::sampling` covers each face with balls and argues why that suffices.
//!
//! Everything else only makes fewer pixels covered or more pixels tested: polygons left out
//! (near `p`, not planar, skipped by the BVH traversal because they can no longer lower any
//! pixel that matters, or no nearer than the farthest occludee reaching any tile they touch),
//! bounding rectangles, `f32` rounding with margins.

mod hemicube;
mod sweep;

pub use hemicube::{BoxRect, BoxTest, Hemicube, RenderStats};
pub use sweep::{Occludees, RectSweep, SweepProbe, SweepStats};

use crate::geom::{Aabb, DAabb};
use crate::project::occluders::{Occluders, PartKind, polygon_inradius};
use crate::scene::alpha::Coverage;
use crate::scene::{Scene, is_degenerate};
use glam::{DVec2, DVec3, Vec3};
use obvhs::bvh2::Bvh2;
use rayon::prelude::*;
use std::sync::Arc;

/// The axes of the five views from a point of the face with outward normal `sign × e_axis`
/// (the hemicube's and the sweep's): the front view, then the outer halves of the side
/// views. View `k`'s `X`, `Y`, `Z` are `s × q[ax]` for its `(ax, s)` of a point `q` relative
/// to the eye ([`view_coords`]).
pub(crate) fn view_maps(axis: usize, sign: f64) -> [[(usize, f64); 3]; 5] {
    let (a, b, c) = (axis, (axis + 1) % 3, (axis + 2) % 3);
    [
        [(b, 1.0), (c, 1.0), (a, sign)],
        [(c, 1.0), (a, sign), (b, 1.0)],
        [(c, 1.0), (a, sign), (b, -1.0)],
        [(b, 1.0), (a, sign), (c, 1.0)],
        [(b, 1.0), (a, sign), (c, -1.0)],
    ]
}

/// `p` (relative to the eye) in the coordinates of the view whose axes are `map`
/// ([`view_maps`]).
#[inline]
pub(crate) fn view_coords(map: [(usize, f64); 3], p: DVec3) -> DVec3 {
    DVec3::new(
        map[0].1 * p[map[0].0],
        map[1].1 * p[map[1].0],
        map[2].1 * p[map[2].0],
    )
}

/// One convex planar occluder polygon of the sampler.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SamplePoly {
    /// Start of its vertices in [`SampleOccluders::points`].
    pub start: u32,
    /// End (exclusive) of its vertices.
    pub end: u32,
    /// The scene object it belongs to.
    pub object: u32,
}

/// The sampler's occluders: exactly planar convex polygons (a leaf triangle, coplanar
/// triangles merged by [`crate::project::occluders`]) with a BVH over their boxes.
#[derive(Default)]
pub struct SampleOccluders {
    /// Vertices of all polygons (scene coordinates; each an exact `f32` scene vertex).
    pub points: Vec<DVec3>,
    /// The polygons.
    pub polys: Vec<SamplePoly>,
    /// The BVH over the polygons' bounds, rounded outward to `f32` (None without polygons;
    /// the exact bounds are [`SampleOccluders::poly_bounds`], not stored: 48 bytes a polygon,
    /// 380 MB on the paper-size forest).
    pub(crate) bvh: Option<Bvh2>,
    /// Median in-plane inradius of the polygons about their centroids (for the default ε).
    pub median_inradius: f64,
    /// Per polygon: its entry in `cards` when it is a textured card triangle, else
    /// [`NO_CARD`].
    pub card_of: Vec<u32>,
    /// The textured card triangles' texture maps.
    pub cards: Vec<SampleCard>,
    /// The coverages the cards index.
    pub coverages: Vec<Arc<Coverage>>,
}

/// [`SampleOccluders::card_of`] of a polygon that is not a card triangle.
pub const NO_CARD: u32 = u32::MAX;

/// A textured card triangle of the sampler: drawn only where the texture is surely opaque over
/// each pixel's texel footprint (`Hemicube`'s docs). Its texture coordinates are the affine
/// function `uv(x) = uv0 + (gu·(x − origin), gv·(x − origin))` of a point `x` of its plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleCard {
    /// Its coverage in [`SampleOccluders::coverages`].
    pub coverage: u32,
    /// A point of the triangle (its first corner).
    pub origin: DVec3,
    /// Texture coordinates at `origin`.
    pub uv0: DVec2,
    /// Gradients of `u` and `v` in the triangle's plane.
    pub gu: DVec3,
    /// See `gu`.
    pub gv: DVec3,
}

impl SampleCard {
    /// The map of a triangle with corners `p` and texture coordinates `uv`; None when it is
    /// degenerate in space or in texture space.
    pub fn new(p: [DVec3; 3], uv: [DVec2; 3], coverage: u32) -> Option<SampleCard> {
        let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
        let (d1, d2) = (uv[1] - uv[0], uv[2] - uv[0]);
        let n = e1.cross(e2);
        let det = d1.perp_dot(d2);
        if !(n.length_squared() > 0.0 && det != 0.0 && det.is_finite()) {
            return None;
        }
        // The dual basis of (e1, e2) in the plane: b1·e1 = 1, b1·e2 = 0 and the reverse.
        let b1 = e2.cross(n) / e1.dot(e2.cross(n));
        let b2 = n.cross(e1) / e2.dot(n.cross(e1));
        // uv(x) = uv0 + d1·(b1·(x − p0)) + d2·(b2·(x − p0)).
        let gu = b1 * d1.x + b2 * d2.x;
        let gv = b1 * d1.y + b2 * d2.y;
        (gu.is_finite() && gv.is_finite()).then_some(SampleCard {
            coverage,
            origin: p[0],
            uv0: uv[0],
            gu,
            gv,
        })
    }

    /// Texture coordinates of a point of the plane.
    pub fn uv(&self, x: DVec3) -> DVec2 {
        let d = x - self.origin;
        self.uv0 + DVec2::new(self.gu.dot(d), self.gv.dot(d))
    }
}

impl std::fmt::Debug for SampleOccluders {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SampleOccluders")
            .field("polys", &self.polys.len())
            .field("median_inradius", &self.median_inradius)
            .field("cards", &self.cards.len())
            .finish()
    }
}

/// A polygon whose inradius is under this fraction of its longest edge is a sliver and does
/// not count for the default ε (a leaf triangle's is about 0.2, a 1:100 strip's 0.005).
pub const SLIVER_RATIO: f64 = 1e-3;

/// Whether a polygon with these points and inradius `r` is a sliver: its inradius under
/// [`SLIVER_RATIO`] of its longest edge.
fn is_sliver(pts: &[DVec3], r: f64) -> bool {
    let longest = (0..pts.len())
        .map(|k| pts[k].distance(pts[(k + 1) % pts.len()]))
        .fold(0.0, f64::max);
    r.is_nan() || r < SLIVER_RATIO * longest
}

struct PolyBox(obvhs::aabb::Aabb);
impl obvhs::Boundable for PolyBox {
    fn aabb(&self) -> obvhs::aabb::Aabb {
        self.0
    }
}

impl SampleOccluders {
    /// The sampler's polygons from a scene's occluder parts: exactly planar polygon parts as
    /// they are; for objects with a solid part or a polygon that is not exactly planar, their
    /// usable triangles instead (each planar; `opaque` unless `alpha_occluders`).
    pub fn new(scene: &Scene, occ: &Occluders, alpha_occluders: bool) -> Self {
        let mut raw = vec![false; scene.objects.len()];
        for p in &occ.parts {
            match p.kind {
                PartKind::Solid { .. } => raw[p.object as usize] = true,
                PartKind::Polygon { .. } if p.deviation > 0.0 => raw[p.object as usize] = true,
                PartKind::Polygon { .. } => {}
            }
        }
        let mut out = SampleOccluders::default();
        let mut inradii = Vec::new();
        for (k, p) in occ.parts.iter().enumerate() {
            // Card polygons are always taken as they are (exactly planar, inside the card).
            if (raw[p.object as usize] && !p.card) || !matches!(p.kind, PartKind::Polygon { .. }) {
                continue;
            }
            let before = out.polys.len();
            out.push(occ.part_points(k), p.object);
            if out.polys.len() > before {
                inradii.push(p.inradius);
            }
        }
        for (o, obj) in scene.objects.iter().enumerate() {
            if !raw[o] {
                continue;
            }
            for t in obj.triangles.clone() {
                let t = t as usize;
                let tri = scene.triangle(t);
                if (!scene.opaque[t] && !alpha_occluders) || is_degenerate(tri) {
                    continue;
                }
                out.push(&tri.map(Vec3::as_dvec3), o as u32);
            }
        }
        // Textured card triangles, tested per pixel against their texel footprint (the card
        // polygons above are their inner approximation for sub-pixel masks and the planes).
        if let Some(a) = scene.alpha.as_ref() {
            out.coverages = occ.card_coverages.clone();
            for &(t, c) in &occ.card_triangles {
                // A texture with no surely opaque cell (a leaf atlas over all its mip levels)
                // covers no pixel: leave its triangles out.
                let Some(card) = a.card(t as usize) else {
                    continue;
                };
                if occ.card_coverages[c as usize].opaque_share <= 0.0 {
                    continue;
                }
                let p = scene.triangle(t as usize).map(Vec3::as_dvec3);
                if let Some(sc) = SampleCard::new(p, card.uv.map(|u| u.as_dvec2()), c) {
                    out.push_card(&p, sc, scene.triangle_object(t));
                }
            }
        }
        // Triangles merged alone have no inradius recorded: take it from the geometry.
        for (i, r) in inradii.iter_mut().enumerate() {
            if *r <= 0.0 {
                *r = polygon_inradius(out.poly_points(i));
            }
        }
        if inradii.is_empty() {
            // Only raw triangles: their inradii from the geometry.
            inradii = (0..out.polys.len())
                .map(|i| polygon_inradius(out.poly_points(i)))
                .collect();
        }
        // Slivers (degenerate or nearly: welded CAD seams, needles) occlude next to nothing
        // but would set a tiny ε, and with it millions of sample points: the median is taken
        // over the polygons that are not slivers, when there are any.
        let fat: Vec<f64> = inradii
            .iter()
            .enumerate()
            .filter(|&(i, &r)| !is_sliver(out.poly_points(i), r))
            .map(|(_, &r)| r)
            .collect();
        if !fat.is_empty() {
            inradii = fat;
        }
        if !inradii.is_empty() {
            let m = inradii.len() / 2;
            inradii.select_nth_unstable_by(m, f64::total_cmp);
            out.median_inradius = inradii[m];
        }
        out.build_bvh();
        out
    }

    /// A set of polygons given directly (tests, tools). Each must be convex and exactly
    /// planar; degenerate ones are dropped.
    pub fn from_polygons(polys: &[(Vec<DVec3>, u32)]) -> Self {
        Self::from_polygons_and_cards(polys, &[], Vec::new())
    }

    /// [`SampleOccluders::from_polygons`] with textured card triangles (corners, texture
    /// coordinates, index into `coverages`, object) too.
    pub fn from_polygons_and_cards(
        polys: &[(Vec<DVec3>, u32)],
        cards: &[([DVec3; 3], [DVec2; 3], u32, u32)],
        coverages: Vec<Arc<Coverage>>,
    ) -> Self {
        let mut out = SampleOccluders::default();
        for (pts, object) in polys {
            out.push(pts, *object);
        }
        out.coverages = coverages;
        for &(p, uv, c, object) in cards {
            assert!(
                (c as usize) < out.coverages.len(),
                "coverage index in range"
            );
            if let Some(sc) = SampleCard::new(p, uv, c) {
                out.push_card(&p, sc, object);
            }
        }
        out.build_bvh();
        out
    }

    fn push_card(&mut self, p: &[DVec3; 3], card: SampleCard, object: u32) {
        let n = self.polys.len();
        self.push(p, object);
        if self.polys.len() > n {
            self.card_of.resize(n, NO_CARD);
            self.card_of.push(self.cards.len() as u32);
            self.cards.push(card);
        }
    }

    /// The card map of polygon `i`, when it is a textured card triangle.
    pub fn card(&self, i: usize) -> Option<&SampleCard> {
        match self.card_of.get(i) {
            Some(&c) if c != NO_CARD => Some(&self.cards[c as usize]),
            _ => None,
        }
    }

    /// Builds the BVH over the polygons' boxes (none without polygons).
    fn build_bvh(&mut self) {
        if self.polys.is_empty() {
            self.bvh = None;
            return;
        }
        let boxes: Vec<PolyBox> = (0..self.polys.len())
            .into_par_iter()
            .map(|i| {
                // Rounded outward: every polygon lies inside its f32 box.
                let b = self.poly_bounds(i);
                let f = Aabb::outward(b.min, b.max);
                PolyBox(obvhs::aabb::Aabb::new(f.min.into(), f.max.into()))
            })
            .collect();
        let mut t = std::time::Duration::ZERO;
        let mut bvh =
            obvhs::bvh2::builder::build_bvh2(&boxes, obvhs::BvhBuildParams::fast_build(), &mut t);
        // Store the polygons in the BVH's leaf order, so that a traversal reads them (and
        // their points) from consecutive memory. (In parallel: the paper-size forest's 7.9 M
        // polygons took 3.7 s on one thread.)
        let order = &bvh.primitive_indices;
        let old_polys = &self.polys;
        let mut polys: Vec<SamplePoly> = order
            .par_iter()
            .map(|&slot| {
                let p = old_polys[slot as usize];
                SamplePoly {
                    start: 0,
                    end: p.end - p.start,
                    object: p.object,
                }
            })
            .collect();
        let mut start = 0u32;
        for p in &mut polys {
            p.start = start;
            start += p.end;
            p.end = start;
        }
        let old_points = &self.points;
        let points: Vec<DVec3> = order
            .par_iter()
            .flat_map_iter(|&slot| {
                let p = old_polys[slot as usize];
                old_points[p.start as usize..p.end as usize].iter().copied()
            })
            .collect();
        let card_of: Vec<u32> = if self.cards.is_empty() {
            Vec::new()
        } else {
            order
                .iter()
                .map(|&slot| self.card_of.get(slot as usize).copied().unwrap_or(NO_CARD))
                .collect()
        };
        for (k, slot) in bvh.primitive_indices.iter_mut().enumerate() {
            *slot = k as u32;
        }
        self.points = points;
        self.polys = polys;
        self.card_of = card_of;
        self.bvh = Some(bvh);
    }

    fn push(&mut self, pts: &[DVec3], object: u32) {
        if pts.len() < 3 {
            return;
        }
        let start = self.points.len() as u32;
        self.points.extend_from_slice(pts);
        self.polys.push(SamplePoly {
            start,
            end: self.points.len() as u32,
            object,
        });
    }

    /// The vertices of polygon `i`.
    pub fn poly_points(&self, i: usize) -> &[DVec3] {
        let p = self.polys[i];
        &self.points[p.start as usize..p.end as usize]
    }

    /// The exact bounds of polygon `i`.
    pub fn poly_bounds(&self, i: usize) -> DAabb {
        let mut b = DAabb::EMPTY;
        for &q in self.poly_points(i) {
            b.grow(q);
        }
        b
    }
}
