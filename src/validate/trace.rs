//! Ray casting for the validator: [`SceneRays`], a compressed wide BVH (`obvhs` CWBVH) over
//! the scene's non-degenerate triangles, a watertight ray/triangle test, first-hit tracing with
//! see-through (alpha-tested) triangles, and area-weighted point sampling on objects.
//!
//! Alpha-tested cards (glTF `MASK`, [`crate::scene::alpha`]) are traced as a renderer at
//! full resolution draws them: a hit where the card's bilinear mip-0 alpha reaches the
//! cutoff blocks like an opaque triangle; a hit on a transparent texel is no hit at all.
//!
//! Robustness matters more than usual here: a ray that leaks through the shared edge of two
//! wall triangles would "see" an object that is really hidden and report a false cull that is
//! not there. Hence:
//! * the triangle test is the watertight one of Woop, Benthin and Wald (JCGT 2013): a shared
//!   edge gives exactly opposite edge functions in both triangles, and exact zeros are
//!   re-evaluated in double precision, so a ray through a closed mesh always hits it;
//! * the boxes the BVH is built from are padded a little, so the single-precision slab tests
//!   of the traversal never reject a box whose triangle the ray hits;
//! * zero-area triangles are left out: they never block and never name an object.

use crate::geom::Aabb;
use crate::scene::alpha::{AlphaCards, NO_CARD};
use crate::scene::{self, Scene};
use glam::{DVec3, UVec2, Vec3, Vec3A};
use obvhs::BvhBuildParams;
use obvhs::aabb::Aabb as BvhAabb;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::Ray;

/// One triangle a ray reaches before (or at) its first blocking hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TraceHit {
    /// The object owning the triangle.
    pub object: u32,
    /// The triangle's index in [`Scene::triangles`].
    pub triangle: u32,
    /// Distance along the ray, in units of the direction's length.
    pub t: f32,
}

/// A hit as the traversal records it: BVH slot and distance.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RawHit {
    pub slot: u32,
    pub t: f32,
}

/// Per-triangle data in BVH order.
#[derive(Clone, Copy, Debug)]
pub(crate) struct TriMeta {
    pub object: u32,
    pub triangle: u32,
    pub opaque: bool,
    /// Index into the scene's alpha cards, or [`NO_CARD`].
    pub card: u32,
}

/// Area-weighted sampling data of one object: its run of `SceneRays::samples`.
#[derive(Clone, Debug)]
struct ObjectArea {
    start: u32,
    end: u32,
}

/// One entry of an alias table (Walker/Vose): entry `i` is kept with probability `keep`,
/// else entry `alias` (both local to the object's run) is taken.
#[derive(Clone, Copy, Debug)]
struct AliasEntry {
    keep: f32,
    alias: u32,
}

/// A triangle to sample points on, with its alias-table entry (one cache line together).
#[derive(Clone, Copy, Debug)]
struct SampleTri {
    corners: [Vec3; 3],
    entry: AliasEntry,
}

/// The ray-casting structure of one scene: built once, shared by all cells and threads.
pub struct SceneRays {
    bvh: CwBvh,
    /// Triangle corners in BVH order (slot `i` is `bvh.primitive_indices[i]`).
    tris: Vec<[Vec3A; 3]>,
    /// Per slot: owner object, scene triangle index, opacity.
    meta: Vec<TriMeta>,
    /// Per object: its run of the area tables.
    areas: Vec<ObjectArea>,
    /// Per object, its non-degenerate triangles with an area-weighted alias table.
    samples: Vec<SampleTri>,
    /// Objects with at least one non-degenerate triangle, ascending.
    targetable: Vec<u32>,
    /// Object bounds, as in the scene.
    bounds: Vec<Aabb>,
    /// The scene's alpha-tested cards (their alpha test at mip 0), if any.
    alpha: Option<AlphaCards>,
}

impl std::fmt::Debug for SceneRays {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SceneRays")
            .field("triangles", &self.tris.len())
            .field("bvh_nodes", &self.bvh.nodes.len())
            .field("targetable_objects", &self.targetable.len())
            .finish()
    }
}

/// Rays per scene triangle from which [`SceneRays::for_rays`] takes the slow build: on the
/// paper-size forest its 24 s more than `fast_build` pay back at about 0.6 µs a ray, from
/// about 40 M rays (5 per triangle; [`SceneRays::with_build`] has the figures).
pub const SLOW_BUILD_RAYS_PER_TRIANGLE: u64 = 5;

impl SceneRays {
    /// Builds the BVH over all non-degenerate triangles of `scene` (single-threaded PLOC
    /// build, then CWBVH conversion) and the per-object area tables, with obvhs'
    /// `slow_build`: for tracing millions of rays ([`SceneRays::with_build`] for fewer).
    ///
    /// The scene should satisfy [`Scene::validate`] (indices in range, objects covering the
    /// triangles in order); [`crate::validate::check`] checks that before calling this.
    pub fn new(scene: &Scene) -> SceneRays {
        Self::with_build(scene, BvhBuildParams::slow_build())
    }

    /// [`SceneRays::new`] or, for fewer than [`SLOW_BUILD_RAYS_PER_TRIANGLE`] rays per
    /// triangle in all, [`SceneRays::with_build`] with obvhs' `fast_build`: the build that
    /// costs least for `rays` rays (the same hits either way).
    pub fn for_rays(scene: &Scene, rays: u64) -> SceneRays {
        let triangles = scene.triangles.len() as u64;
        if rays >= triangles.saturating_mul(SLOW_BUILD_RAYS_PER_TRIANGLE) {
            Self::new(scene)
        } else {
            Self::with_build(scene, BvhBuildParams::fast_build())
        }
    }

    /// [`SceneRays::new`] with another BVH build: a faster build traces more slowly. Measured
    /// on the paper-size forest (7.9 M triangles, 300,000 random rays from its middle cell,
    /// one thread): `slow_build` 32.4 s to build and 1.45 µs a ray, `medium_build` 11.3 s and
    /// 1.86 µs, `fast_build` 8.1 s and 2.07 µs, so `slow_build` pays from about 40 M rays; on
    /// the fine forest (1.5 M) 4.4 s against 1.4 s for the same speed. Every build finds the
    /// same hits.
    pub fn with_build(scene: &Scene, params: BvhBuildParams) -> SceneRays {
        let nt = scene.triangles.len();
        let mut kept: Vec<u32> = Vec::with_capacity(nt);
        let mut boxes: Vec<BvhAabb> = Vec::with_capacity(nt);
        // Padding of the BVH input boxes: far above the rounding error of the slab tests
        // (a few ulps of the coordinates), far below any feature size that matters.
        let scale = scene_scale(scene);
        let pad = Vec3A::splat(scale * 1e-5);
        for t in 0..nt {
            let tri = scene.triangle(t);
            if scene::is_degenerate(tri) {
                continue;
            }
            let mut b = BvhAabb::from_points(&tri.map(Vec3A::from));
            b.min -= pad;
            b.max += pad;
            kept.push(t as u32);
            boxes.push(b);
        }

        let bvh = if boxes.is_empty() {
            CwBvh::default()
        } else {
            // (`new`: `slow_build`, wider PLOC search and more reinsertion: about 2–4 s for a
            // million triangles, and 15–30 % faster traversal than `medium_build` on the
            // generated city and forest, which pays off over millions of rays per cell.)
            obvhs::cwbvh::builder::build_cwbvh(&boxes, params, &mut std::time::Duration::default())
        };
        let mut tris = Vec::with_capacity(bvh.primitive_indices.len());
        let mut meta = Vec::with_capacity(bvh.primitive_indices.len());
        for &p in &bvh.primitive_indices {
            let t = kept[p as usize];
            tris.push(scene.triangle(t as usize).map(Vec3A::from));
            meta.push(TriMeta {
                object: scene.triangle_object(t),
                triangle: t,
                opaque: scene.opaque[t as usize],
                card: scene
                    .alpha
                    .as_ref()
                    .map_or(NO_CARD, |a| a.card_of[t as usize]),
            });
        }

        let mut areas = Vec::with_capacity(scene.objects.len());
        let mut samples: Vec<SampleTri> = Vec::new();
        let mut targetable = Vec::new();
        let mut weights = Vec::new();
        for (id, o) in scene.objects.iter().enumerate() {
            let start = samples.len() as u32;
            weights.clear();
            for t in o.triangles.clone() {
                let tri = scene.triangle(t as usize);
                let [a, b, c] = tri.map(|p| p.as_dvec3());
                let area = 0.5 * (b - a).cross(c - a).length();
                if area > 0.0 && area.is_finite() && !scene::is_degenerate(tri) {
                    weights.push(area);
                    samples.push(SampleTri {
                        corners: tri,
                        entry: AliasEntry {
                            keep: 1.0,
                            alias: 0,
                        },
                    });
                }
            }
            for (s, e) in samples[start as usize..]
                .iter_mut()
                .zip(alias_table(&weights))
            {
                s.entry = e;
            }
            let end = samples.len() as u32;
            if end > start {
                targetable.push(id as u32);
            }
            areas.push(ObjectArea { start, end });
        }

        SceneRays {
            bvh,
            tris,
            meta,
            areas,
            samples,
            targetable,
            bounds: scene.objects.iter().map(|o| o.bounds).collect(),
            alpha: scene.alpha.clone(),
        }
    }

    /// Number of triangles in the BVH (the scene's non-degenerate triangles).
    pub fn triangles(&self) -> usize {
        self.tris.len()
    }

    /// Objects that have at least one non-degenerate triangle (the only ones a ray can
    /// find), ascending.
    pub fn targetable_objects(&self) -> &[u32] {
        &self.targetable
    }

    /// Traces one ray and returns what it sees, nearest first: every see-through triangle in
    /// front of the first blocking triangle, then the blocking triangle(s) (several only when
    /// they are hit at exactly the same distance). A triangle blocks when it is opaque, or
    /// always when `alpha_blocks` is true.
    ///
    /// `direction` need not be normalised but must be finite and non-zero.
    pub fn trace(&self, origin: Vec3, direction: Vec3, alpha_blocks: bool) -> Vec<TraceHit> {
        let mut raw = Vec::new();
        self.trace_raw(origin, direction, alpha_blocks, &mut raw);
        let mut out: Vec<TraceHit> = raw
            .iter()
            .map(|h| {
                let m = self.meta[h.slot as usize];
                TraceHit {
                    object: m.object,
                    triangle: m.triangle,
                    t: h.t,
                }
            })
            .collect();
        out.sort_by(|a, b| a.t.total_cmp(&b.t).then(a.triangle.cmp(&b.triangle)));
        out
    }

    /// The hits of one ray into `hits` (cleared first), in traversal order.
    #[inline]
    pub(crate) fn trace_raw(
        &self,
        origin: Vec3,
        direction: Vec3,
        alpha_blocks: bool,
        hits: &mut Vec<RawHit>,
    ) {
        self.trace_raw_until(origin, direction, f32::INFINITY, alpha_blocks, hits);
    }

    /// [`SceneRays::trace_raw`] for the segment `t ∈ [0, tmax]` of the ray (in units of the
    /// direction's length): the same hits as the whole ray up to `tmax`, and nothing beyond.
    /// Used by `--hunt`, whose rays only need to reach the far side of one object's bounds.
    #[inline]
    pub(crate) fn trace_raw_until(
        &self,
        origin: Vec3,
        direction: Vec3,
        tmax: f32,
        alpha_blocks: bool,
        hits: &mut Vec<RawHit>,
    ) {
        hits.clear();
        if self.tris.is_empty() || tmax.is_nan() || tmax < 0.0 {
            return;
        }
        let o = Vec3A::from(origin);
        let d = Vec3A::from(direction);
        let shear = Shear::new(o, d);
        let mut ray = Ray::new(o, d, 0.0, tmax);
        let mut state = self.bvh.new_traversal(d);
        let mut node;
        obvhs::traverse!(
            self.bvh,
            node,
            state,
            node.intersect_ray(&ray, state.oct_inv4),
            {
                let slot = state.primitive_id;
                if let Some(t) = shear.intersect(&self.tris[slot as usize], ray.tmax) {
                    let m = &self.meta[slot as usize];
                    // A card is seen only where it is drawn; a transparent texel lets the ray
                    // pass and shows nothing.
                    let drawn = alpha_blocks
                        || m.card == NO_CARD
                        || self.card_drawn(slot, m.card, origin, direction, t);
                    let blocks = drawn && (alpha_blocks || m.opaque || m.card != NO_CARD);
                    if drawn {
                        hits.push(RawHit { slot, t });
                    }
                    if t < ray.tmax && blocks {
                        ray.tmax = t;
                    }
                }
            }
        );
        let tmax = ray.tmax;
        hits.retain(|h| h.t <= tmax);
    }

    /// Whether card `card` (BVH slot `slot`) is drawn where the ray meets it at `t`.
    fn card_drawn(&self, slot: u32, card: u32, origin: Vec3, direction: Vec3, t: f32) -> bool {
        let Some(a) = &self.alpha else { return true };
        let [p0, p1, p2] = self.tris[slot as usize].map(|v| Vec3::from(v).as_dvec3());
        let p = origin.as_dvec3() + direction.as_dvec3() * t as f64;
        let (v0, v1, v2) = (p1 - p0, p2 - p0, p - p0);
        let (d00, d01, d11) = (v0.dot(v0), v0.dot(v1), v1.dot(v1));
        let (d20, d21) = (v2.dot(v0), v2.dot(v1));
        let denom = d00 * d11 - d01 * d01;
        if denom.abs() <= 0.0 || !denom.is_finite() {
            return true;
        }
        let b1 = ((d11 * d20 - d01 * d21) / denom).clamp(0.0, 1.0);
        let b2 = ((d00 * d21 - d01 * d20) / denom).clamp(0.0, 1.0 - b1);
        a.drawn_at(&a.cards[card as usize], b1 as f32, b2 as f32)
    }

    #[inline]
    pub(crate) fn meta(&self, slot: u32) -> TriMeta {
        self.meta[slot as usize]
    }

    /// The bounds of object `o`.
    #[inline]
    pub(crate) fn object_bounds(&self, o: u32) -> Aabb {
        self.bounds[o as usize]
    }

    /// A point on the surface of object `o`, area-weighted over its non-degenerate
    /// triangles (alias table, O(1)), from three uniform numbers in [0, 1). `None` when the
    /// object has no area.
    pub(crate) fn surface_point(&self, o: u32, pick: f64, r1: f64, r2: f64) -> Option<DVec3> {
        let a = &self.areas[o as usize];
        let n = a.end - a.start;
        if n == 0 {
            return None;
        }
        let x = pick * f64::from(n);
        let i = (x as u32).min(n - 1);
        let mut tri = &self.samples[(a.start + i) as usize];
        if x - f64::from(i) >= f64::from(tri.entry.keep) {
            tri = &self.samples[(a.start + tri.entry.alias) as usize];
        }
        let [p0, p1, p2] = tri.corners.map(|p| p.as_dvec3());
        let s = r1.sqrt();
        Some(p0 * (1.0 - s) + p1 * (s * (1.0 - r2)) + p2 * (s * r2))
    }

    /// Number of non-degenerate triangles of object `o` (those [`SceneRays::object_triangle`]
    /// picks from).
    #[inline]
    pub(crate) fn object_triangle_count(&self, o: u32) -> u32 {
        let a = &self.areas[o as usize];
        a.end - a.start
    }

    /// The corners of non-degenerate triangle `i` (`< object_triangle_count(o)`) of object
    /// `o`, in the object's order.
    #[inline]
    pub(crate) fn object_triangle(&self, o: u32, i: u32) -> [Vec3; 3] {
        self.samples[(self.areas[o as usize].start + i) as usize].corners
    }

    /// The point where a witness ray meets scene triangle `t`, in double precision (plane
    /// intersection), falling back to `origin + t_f32 * direction` for an edge-on hit.
    pub(crate) fn precise_hit(
        scene: &Scene,
        triangle: u32,
        origin: Vec3,
        direction: Vec3,
        t: f32,
    ) -> Vec3 {
        let [a, b, c] = scene.triangle(triangle as usize).map(|p| p.as_dvec3());
        let o = origin.as_dvec3();
        let d = direction.as_dvec3();
        let n = (b - a).cross(c - a);
        let den = n.dot(d);
        let tt = if den != 0.0 {
            n.dot(a - o) / den
        } else {
            f64::from(t)
        };
        (o + d * tt).as_vec3()
    }
}

/// The alias table (Vose's method) of positive `weights`: sampling entry `i` uniformly, then
/// keeping it with probability `keep` or else taking `alias`, picks `i` with probability
/// proportional to `weights[i]`.
fn alias_table(weights: &[f64]) -> Vec<AliasEntry> {
    let n = weights.len();
    let total: f64 = weights.iter().sum();
    let mut table = vec![
        AliasEntry {
            keep: 1.0,
            alias: 0
        };
        n
    ];
    if n == 0 || total.is_nan() || total <= 0.0 {
        return table;
    }
    let mut p: Vec<f64> = weights.iter().map(|w| w * n as f64 / total).collect();
    let (mut small, mut large): (Vec<usize>, Vec<usize>) = (0..n).partition(|&i| p[i] < 1.0);
    while let (Some(&s), Some(&l)) = (small.last(), large.last()) {
        small.pop();
        table[s] = AliasEntry {
            keep: p[s] as f32,
            alias: l as u32,
        };
        p[l] -= 1.0 - p[s];
        if p[l] < 1.0 {
            large.pop();
            small.push(l);
        }
    }
    // Left-overs (rounding) keep themselves.
    for i in small.into_iter().chain(large) {
        table[i] = AliasEntry {
            keep: 1.0,
            alias: i as u32,
        };
    }
    table
}

/// A length that stands for the size of the scene: the largest absolute coordinate plus the
/// largest extent (1 for an empty scene).
fn scene_scale(scene: &Scene) -> f32 {
    let b = scene.bounds();
    if b.is_empty() {
        return 1.0;
    }
    let m = b.min.abs().max(b.max.abs()).max_element() + b.size().max_element();
    if m.is_finite() && m > 0.0 { m } else { 1.0 }
}

/// The per-ray part of the watertight test: a shear that maps the ray to the +z axis.
///
/// `mx`, `my` and `mz` hold the shear as dot products so the per-triangle work is a few
/// SIMD operations. Each vertex's transformed coordinates depend only on the vertex and the
/// ray, which is all watertightness needs.
#[derive(Clone, Copy, Debug)]
struct Shear {
    origin: Vec3A,
    mx: Vec3A,
    my: Vec3A,
    mz: Vec3A,
}

impl Shear {
    #[inline]
    fn new(origin: Vec3A, d: Vec3A) -> Shear {
        let a = d.abs();
        let kz = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let sx = d[kx] / d[kz];
        let sy = d[ky] / d[kz];
        let sz = 1.0 / d[kz];
        let mut mx = Vec3A::ZERO;
        mx[kx] = 1.0;
        mx[kz] = -sx;
        let mut my = Vec3A::ZERO;
        my[ky] = 1.0;
        my[kz] = -sy;
        let mut mz = Vec3A::ZERO;
        mz[kz] = sz;
        Shear { origin, mx, my, mz }
    }

    /// Distance to the triangle when the ray hits it with `0 <= t <= tmax`.
    #[inline(always)]
    fn intersect(&self, tri: &[Vec3A; 3], tmax: f32) -> Option<f32> {
        let a = tri[0] - self.origin;
        let b = tri[1] - self.origin;
        let c = tri[2] - self.origin;
        let (ax, ay) = (a.dot(self.mx), a.dot(self.my));
        let (bx, by) = (b.dot(self.mx), b.dot(self.my));
        let (cx, cy) = (c.dot(self.mx), c.dot(self.my));
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        if u == 0.0 || v == 0.0 || w == 0.0 {
            // Exact in double precision: products of two floats fit a double.
            let e = |px: f32, py: f32, qx: f32, qy: f32| {
                (f64::from(px) * f64::from(qy) - f64::from(py) * f64::from(qx)) as f32
            };
            u = e(cx, cy, bx, by);
            v = e(ax, ay, cx, cy);
            w = e(bx, by, ax, ay);
        }
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let mut det = u + v + w;
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let (az, bz, cz) = (a.dot(self.mz), b.dot(self.mz), c.dot(self.mz));
        let mut tt = u * az + v * bz + w * cz;
        if det < 0.0 {
            tt = -tt;
            det = -det;
        }
        if tt.is_nan() || tt < 0.0 || tt > tmax * det {
            return None;
        }
        let t = tt / det;
        (t.is_finite() && t <= tmax).then_some(t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::vec3;
    use std::path::Path;

    fn quad(z: f32, half: f32) -> Vec<[Vec3; 3]> {
        let (a, b, c, d) = (
            vec3(-half, -half, z),
            vec3(half, -half, z),
            vec3(half, half, z),
            vec3(-half, half, z),
        );
        vec![[a, b, c], [a, c, d]]
    }

    #[test]
    fn ray_through_the_shared_diagonal_of_a_quad_hits_it() {
        let scene = Scene::from_objects(
            Path::new("mem"),
            vec![("wall".into(), quad(5.0, 1.0), true)],
        );
        let rays = SceneRays::new(&scene);
        assert_eq!(rays.triangles(), 2);
        // The diagonal from (-1,-1) to (1,1): points (s, s, 5).
        for i in 0..2001 {
            let s = -0.999 + 1.998 * (i as f32) / 2000.0;
            let hits = rays.trace(Vec3::ZERO, vec3(s, s, 5.0), false);
            assert!(!hits.is_empty(), "leak through the diagonal at s = {s}");
            assert!(hits.iter().all(|h| h.object == 0));
        }
    }

    #[test]
    fn every_build_finds_the_same_hits() {
        // The demo forest (thousands of leaves and trunks on a ground), rays from inside it.
        let g = crate::generate::forest(&crate::generate::ForestOptions {
            trees: 40,
            ..crate::generate::ForestOptions::demo()
        })
        .expect("forest");
        let scene = g.to_scene("mem");
        let slow = SceneRays::new(&scene);
        let fast = SceneRays::with_build(&scene, BvhBuildParams::fast_build());
        assert_ne!(
            slow.bvh.nodes.len(),
            fast.bvh.nodes.len(),
            "the builds must differ for the test to mean anything"
        );
        let b = g.cells[0];
        let mut state = 3u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut hits = 0;
        for _ in 0..20_000 {
            let o = b.min + (b.max - b.min) * vec3(next(), next(), next());
            let d = vec3(next() - 0.5, next() - 0.5, next() - 0.5);
            let a = slow.trace(o, d, false);
            assert_eq!(a, fast.trace(o, d, false), "ray {o:?} {d:?}");
            hits += a.len();
        }
        assert!(hits > 10_000, "the rays must hit things: {hits}");
        // `for_rays` takes the slow build for many rays only.
        let tris = scene.triangles.len() as u64;
        let many = SceneRays::for_rays(&scene, tris * SLOW_BUILD_RAYS_PER_TRIANGLE);
        let few = SceneRays::for_rays(&scene, tris * SLOW_BUILD_RAYS_PER_TRIANGLE - 1);
        assert_eq!(many.bvh.nodes.len(), slow.bvh.nodes.len());
        assert_eq!(few.bvh.nodes.len(), fast.bvh.nodes.len());
    }

    #[test]
    fn a_single_triangle_scene_is_traced() {
        let tri = vec![[
            vec3(-1.0, -1.0, 3.0),
            vec3(1.0, -1.0, 3.0),
            vec3(0.0, 1.0, 3.0),
        ]];
        let scene = Scene::from_objects(Path::new("mem"), vec![("t".into(), tri, true)]);
        let rays = SceneRays::new(&scene);
        let hits = rays.trace(Vec3::ZERO, Vec3::Z, false);
        assert_eq!(hits.len(), 1);
        assert!((hits[0].t - 3.0).abs() < 1e-6);
        assert!(rays.trace(Vec3::ZERO, -Vec3::Z, false).is_empty());
    }

    #[test]
    fn segment_trace_stops_at_tmax() {
        let scene = Scene::from_objects(
            Path::new("mem"),
            vec![
                ("near".into(), quad(4.0, 1.0), false),
                ("far".into(), quad(6.0, 1.0), true),
            ],
        );
        let rays = SceneRays::new(&scene);
        let mut hits = Vec::new();
        let objects = |rays: &SceneRays, hits: &[RawHit]| {
            let mut o: Vec<u32> = hits.iter().map(|h| rays.meta(h.slot).object).collect();
            o.sort_unstable();
            o.dedup();
            o
        };
        rays.trace_raw_until(Vec3::ZERO, Vec3::Z, 3.9, false, &mut hits);
        assert!(hits.is_empty());
        rays.trace_raw_until(Vec3::ZERO, Vec3::Z, 5.0, false, &mut hits);
        assert_eq!(objects(&rays, &hits), vec![0]);
        rays.trace_raw_until(Vec3::ZERO, Vec3::Z, 6.5, false, &mut hits);
        assert_eq!(objects(&rays, &hits), vec![0, 1]);
        // A blocking near triangle hides the far one whatever the segment's length.
        rays.trace_raw_until(Vec3::ZERO, Vec3::Z, 6.5, true, &mut hits);
        assert_eq!(objects(&rays, &hits), vec![0]);
        rays.trace_raw_until(Vec3::ZERO, Vec3::Z, -1.0, false, &mut hits);
        assert!(hits.is_empty());
    }

    #[test]
    fn see_through_triangles_are_reported_and_passed_unless_they_block() {
        let scene = Scene::from_objects(
            Path::new("mem"),
            vec![
                ("card".into(), quad(2.0, 1.0), false),
                ("wall".into(), quad(4.0, 1.0), true),
                ("behind".into(), quad(6.0, 1.0), true),
            ],
        );
        let rays = SceneRays::new(&scene);
        let d = vec3(0.1, 0.2, 1.0);
        let objs: Vec<u32> = rays
            .trace(Vec3::ZERO, d, false)
            .iter()
            .map(|h| h.object)
            .collect();
        assert_eq!(objs, vec![0, 1]);
        let objs: Vec<u32> = rays
            .trace(Vec3::ZERO, d, true)
            .iter()
            .map(|h| h.object)
            .collect();
        assert_eq!(objs, vec![0]);
    }

    #[test]
    fn degenerate_triangles_are_left_out() {
        let flat = vec![[
            vec3(0.0, 0.0, 2.0),
            vec3(1.0, 1.0, 2.0),
            vec3(2.0, 2.0, 2.0),
        ]];
        let scene = Scene::from_objects(
            Path::new("mem"),
            vec![
                ("flat".into(), flat, true),
                ("wall".into(), quad(4.0, 5.0), true),
            ],
        );
        let rays = SceneRays::new(&scene);
        assert_eq!(rays.triangles(), 2);
        assert_eq!(rays.targetable_objects(), &[1]);
        let hits = rays.trace(Vec3::ZERO, vec3(1.0, 0.5, 2.0), false);
        assert_eq!(hits.len(), 1);
        assert_eq!(hits[0].object, 1);
    }

    #[test]
    fn alias_table_follows_the_weights() {
        let w = [1.0, 3.0, 0.5, 0.5, 5.0];
        let t = alias_table(&w);
        let mut p = [0.0f64; 5];
        for (i, e) in t.iter().enumerate() {
            p[i] += f64::from(e.keep) / 5.0;
            p[e.alias as usize] += (1.0 - f64::from(e.keep)) / 5.0;
        }
        for i in 0..5 {
            assert!((p[i] - w[i] / 10.0).abs() < 1e-6, "{p:?}");
        }
    }

    #[test]
    fn surface_points_lie_on_the_object() {
        let scene = Scene::from_objects(
            Path::new("mem"),
            vec![("wall".into(), quad(4.0, 2.0), true)],
        );
        let rays = SceneRays::new(&scene);
        for i in 0..100 {
            let f = i as f64 / 100.0;
            let p = rays
                .surface_point(0, f, (f * 7.3) % 1.0, (f * 3.1) % 1.0)
                .unwrap();
            assert!((p.z - 4.0).abs() < 1e-9 && p.x.abs() <= 2.0 && p.y.abs() <= 2.0);
        }
    }
}
