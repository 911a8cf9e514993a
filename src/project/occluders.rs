//! Occluder preparation, once per scene: each occluder object is cut into convex parts whose
//! views can be projected whole (the lessons' "per-triangle Projections leave cracks"):
//!
//! - a connected component that is a closed, convex solid (a box) becomes one [`PartKind::Solid`]
//!   point set;
//! - every other triangle joins adjacent coplanar triangles into convex polygons
//!   ([`PartKind::Polygon`]; a lone triangle is a polygon of 3 points).
//!
//! - alpha-tested cards (glTF `MASK`) give the convex polygons of their surely opaque
//!   texels ([`crate::scene::alpha`], flagged [`OccluderPart::card`]) unless the cards are
//!   ignored or `--alpha-occluders` treats whole cards as opaque.
//!
//! Every part is a convex point set whose convex hull lies inside the opaque surface or solid
//! (up to a measured deviation that is removed by shrinking, see [`OccluderPart::deviation`]),
//! so the views of its points are views of real occluding geometry.

use crate::geom::DAabb;
use crate::scene::alpha::{self, CardOptions};
use crate::scene::{Scene, is_degenerate};
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use std::collections::HashMap;

/// The shape of one convex part.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PartKind {
    /// A closed convex solid; the points are its (already shrunk) vertices. Its interior
    /// counts as opaque only for eyes outside it: its hull ([`Occluders::hulls`]) bounds the
    /// unshrunk solid, and a cell overlapping it must not use the part as a solid (a ray from
    /// inside crosses no triangle).
    Solid {
        /// Index of the bounds of the unshrunk solid in [`Occluders::hulls`] (a side table:
        /// solids are few, and an inline box made every part 32 bytes larger, 250 MB on the
        /// paper-size forest).
        hull: u32,
    },
    /// A planar convex polygon, points in order.
    Polygon {
        /// Unit normal of the fitted plane.
        normal: DVec3,
    },
}

/// One convex part of an occluder object.
#[derive(Clone, Debug, PartialEq)]
pub struct OccluderPart {
    /// Start of the part's points in [`Occluders::points`].
    pub start: u32,
    /// End (exclusive) of the part's points in [`Occluders::points`].
    pub end: u32,
    /// Bounds of the part's points.
    pub bounds: DAabb,
    /// Id of the scene object the part belongs to.
    pub object: u32,
    /// Solid or polygon, with the data of each.
    pub kind: PartKind,
    /// For polygons: the largest distance of a vertex from the fitted plane (0 for exact
    /// planes and all triangles). A ray crossing a slightly bent polygon at a grazing angle θ
    /// may pass up to `2·deviation / sin θ` beside it, so per cell such polygons are shrunk in
    /// their plane by that amount (see `project::planes`).
    pub deviation: f64,
    /// For polygons: the distance from the vertex centroid to the nearest edge (in-plane
    /// inradius about the centroid), used to shrink it.
    pub inradius: f64,
    /// True for the surely opaque polygon of an alpha-tested card.
    pub card: bool,
}

/// All occluder parts of a scene.
#[derive(Clone, Debug, Default)]
pub struct Occluders {
    /// The points of all parts; part `k` owns `parts[k].start..parts[k].end`.
    pub points: Vec<DVec3>,
    /// The convex parts.
    pub parts: Vec<OccluderPart>,
    /// Bounds of the unshrunk solids, indexed by [`PartKind::Solid`]'s `hull`.
    pub hulls: Vec<DAabb>,
    /// Counts for the summary.
    pub stats: OccluderStats,
    /// Bounds of all parts (empty — min > max — without parts).
    pub bounds: DAabb,
    /// What the alpha-tested cards gave.
    pub cards: CardStats,
    /// The cards' coverages (one per texture and threshold), for the sampler's per-pixel
    /// texel-footprint test.
    pub card_coverages: Vec<std::sync::Arc<alpha::Coverage>>,
    /// Textured card triangles of occluder objects and their coverage in `card_coverages`.
    pub card_triangles: Vec<(u32, u32)>,
}

/// What the alpha-tested cards gave, for the summary.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CardStats {
    /// Card triangles of occluder objects looked at.
    pub triangles: usize,
    /// Surely opaque polygons made from them.
    pub polygons: usize,
    /// World-space area of the card triangles.
    pub card_area: f64,
    /// World-space area of the polygons (the rest is transparent, or not surely opaque).
    pub opaque_area: f64,
}

/// Counts for the summary.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct OccluderStats {
    /// Triangles used as occluders (opaque, selected, not degenerate).
    pub triangles: usize,
    /// Zero-area triangles skipped.
    pub degenerate: usize,
    /// Convex solids made from closed objects.
    pub solids: usize,
    /// Convex planar polygons (merged coplanar triangles, or single triangles).
    pub polygons: usize,
}

impl Occluders {
    /// The points of part `k` (panics when `k` is out of range).
    pub fn part_points(&self, k: usize) -> &[DVec3] {
        let p = &self.parts[k];
        &self.points[p.start as usize..p.end as usize]
    }

    /// For a solid part, the bounds of the unshrunk solid: a cell overlapping them must not
    /// use the part (an eye inside the solid sees out). `None` for polygons.
    pub fn solid_hull(&self, part: &OccluderPart) -> Option<&DAabb> {
        match part.kind {
            PartKind::Solid { hull } => Some(&self.hulls[hull as usize]),
            PartKind::Polygon { .. } => None,
        }
    }
}

/// Largest component (in triangles) tested for being a convex solid.
const MAX_SOLID_TRIANGLES: usize = 256;

/// Prepares the occluder parts of the selected objects.
///
/// `is_occluder[o]` selects objects; triangles of non-opaque materials are used only when
/// `alpha_occluders` is set. Closed convex components become solids per object; all other
/// triangles are welded across objects (bit-identical positions) and merged into convex
/// coplanar polygons per connected component, so two walls of different objects that share an
/// edge project as one polygon, with no crack at their seam.
pub fn prepare(scene: &Scene, is_occluder: &[bool], alpha_occluders: bool) -> Occluders {
    prepare_with(scene, is_occluder, alpha_occluders, None)
}

/// [`prepare`], plus the surely opaque polygons of the alpha-tested cards of the selected
/// objects when `cards` is given (and `alpha_occluders` is not set: then whole cards are
/// used as opaque triangles).
pub fn prepare_with(
    scene: &Scene,
    is_occluder: &[bool],
    alpha_occluders: bool,
    cards: Option<CardOptions>,
) -> Occluders {
    // 1. Per object: solids, and the triangles left over.
    let per_object: Vec<ObjectParts> = (0..scene.objects.len())
        .into_par_iter()
        .map(|o| {
            if !is_occluder[o] {
                return Default::default();
            }
            prepare_object(scene, o as u32, alpha_occluders)
        })
        .collect();
    let mut out = Occluders::default();
    // 2. Weld the leftover triangles of all objects together.
    let mut rest_all: Vec<[Vec3; 3]> = Vec::new();
    let mut tri_object: Vec<u32> = Vec::new();
    for (o, (pts, parts, hulls, st, rest)) in per_object.into_iter().enumerate() {
        let base = out.points.len() as u32;
        let hull_base = out.hulls.len() as u32;
        out.points.extend(pts);
        out.hulls.extend(hulls);
        out.parts.extend(parts.into_iter().map(|mut p| {
            p.start += base;
            p.end += base;
            if let PartKind::Solid { hull } = &mut p.kind {
                *hull += hull_base;
            }
            p
        }));
        out.stats.triangles += st.triangles;
        out.stats.degenerate += st.degenerate;
        out.stats.solids += st.solids;
        tri_object.extend(std::iter::repeat_n(o as u32, rest.len()));
        rest_all.extend(rest);
    }
    let (ids, verts) = weld(rest_all.as_flattened());
    drop(rest_all);
    let tris: Vec<[u32; 3]> = ids.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    drop(ids);
    // 3. Merge coplanar neighbours per connected component, in parallel (a lone triangle —
    //    every leaf of a forest — is its own polygon, made in place without a merge).
    let comps = components(&verts, &tris);
    let comp =
        |k: usize| &comps.triangles[comps.offsets[k] as usize..comps.offsets[k + 1] as usize];
    let multi: Vec<usize> = (0..comps.len()).filter(|&k| comp(k).len() > 1).collect();
    let merged: Vec<Vec<MergedPolygon>> = multi
        .par_iter()
        .map(|&k| {
            let comp_tris: Vec<[u32; 3]> = comp(k).iter().map(|&t| tris[t as usize]).collect();
            merge_coplanar(&verts, &comp_tris)
        })
        .collect();
    let mut merged = merged.into_iter();
    // (Most components of a forest are one leaf triangle: a part of three points each.)
    out.parts.reserve(comps.len());
    out.points.reserve(3 * comps.len());
    for k in 0..comps.len() {
        let c = comp(k);
        let object = tri_object[c[0] as usize];
        if c.len() == 1 {
            let t = tris[c[0] as usize].map(|i| verts[i as usize]);
            out.stats.polygons += 1;
            push_part(
                &mut out.points,
                &mut out.parts,
                object,
                &t,
                PartKind::Polygon {
                    normal: (t[1] - t[0]).cross(t[2] - t[0]).normalize(),
                },
                0.0,
                0.0,
            );
            continue;
        }
        for poly in merged
            .next()
            .expect("one merge per component of several triangles")
        {
            out.stats.polygons += 1;
            let pts: Vec<DVec3> = poly.verts.iter().map(|&i| verts[i as usize]).collect();
            push_part(
                &mut out.points,
                &mut out.parts,
                object,
                &pts,
                PartKind::Polygon {
                    normal: poly.normal,
                },
                poly.deviation,
                poly.inradius,
            );
        }
    }
    // 4. Alpha-tested cards: their surely opaque polygons.
    if let (Some(opts), Some(a), false) = (cards, &scene.alpha, alpha_occluders) {
        let tris: Vec<u32> = (0..scene.triangles.len() as u32)
            .filter(|&t| {
                a.card_of[t as usize] != alpha::NO_CARD
                    && is_occluder[scene.triangle_object(t) as usize]
                    && !is_degenerate(scene.triangle(t as usize))
            })
            .collect();
        let corners = |t: usize| scene.triangle(t).map(Vec3::as_dvec3);
        let object_of = |t: u32| scene.triangle_object(t);
        let made = alpha::card_occluders(a, &corners, &tris, &object_of, opts);
        out.cards = CardStats {
            triangles: made.triangles,
            polygons: made.polygons.len(),
            card_area: made.card_area,
            opaque_area: made.opaque_area,
        };
        out.card_coverages = made.coverages;
        out.card_triangles = made.textured;
        for (object, pts, normal) in made.polygons {
            let inradius = polygon_inradius(&pts);
            push_part(
                &mut out.points,
                &mut out.parts,
                object,
                &pts,
                PartKind::Polygon { normal },
                0.0,
                inradius,
            );
            out.parts.last_mut().expect("just pushed").card = true;
            out.stats.polygons += 1;
        }
    }
    out.bounds = DAabb {
        min: DVec3::INFINITY,
        max: DVec3::NEG_INFINITY,
    };
    for p in &out.parts {
        out.bounds.min = out.bounds.min.min(p.bounds.min);
        out.bounds.max = out.bounds.max.max(p.bounds.max);
    }
    out
}

/// One object's solids (their points, parts and hulls, the parts' hull indices local to the
/// object), its counts, and its other usable triangles.
type ObjectParts = (
    Vec<DVec3>,
    Vec<OccluderPart>,
    Vec<DAabb>,
    OccluderStats,
    Vec<[Vec3; 3]>,
);

/// Welds bit-identical positions: each of `corners`' index among their distinct positions, and
/// those positions, numbered in order of first occurrence (what a hash map filled in order
/// gives). Sorted in parallel: the paper-size forest's 23.7 M corners took 12 s through a
/// hash map on one thread.
///
/// # Panics
/// Past `u32::MAX` corners; a bake refuses such occluders first
/// (`BakeError::TooManyOccluderCorners`).
fn weld(corners: &[Vec3]) -> (Vec<u32>, Vec<DVec3>) {
    let n = corners.len();
    assert!(
        u32::try_from(n).is_ok(),
        "{n} occluder corners: at most 2^32 can be welded"
    );
    // Each corner's position bits and its index: sorted, equal positions lie together with
    // their first occurrence first.
    let mut sorted: Vec<[u32; 4]> = corners
        .par_iter()
        .enumerate()
        .map(|(i, p)| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits(), i as u32])
        .collect();
    sorted.par_sort_unstable();
    let same = |a: &[u32; 4], b: &[u32; 4]| a[..3] == b[..3];
    // The first occurrences, in order, are the distinct positions' numbers.
    let mut first = vec![false; n];
    for (k, e) in sorted.iter().enumerate() {
        if k == 0 || !same(&sorted[k - 1], e) {
            first[e[3] as usize] = true;
        }
    }
    let mut number = vec![0u32; n];
    let mut verts = Vec::new();
    for (i, &f) in first.iter().enumerate() {
        if f {
            number[i] = verts.len() as u32;
            verts.push(corners[i].as_dvec3());
        }
    }
    drop(first);
    let mut ids = vec![0u32; n];
    let mut k = 0;
    while k < n {
        let id = number[sorted[k][3] as usize];
        let mut e = k;
        while e < n && same(&sorted[k], &sorted[e]) {
            ids[sorted[e][3] as usize] = id;
            e += 1;
        }
        k = e;
    }
    (ids, verts)
}

/// One object's convex solids, and its other usable triangles.
fn prepare_object(scene: &Scene, object: u32, alpha_occluders: bool) -> ObjectParts {
    let mut stats = OccluderStats::default();
    let range = scene.objects[object as usize].triangles.clone();
    // Weld bit-identical positions.
    let mut index: foldhash::HashMap<[u32; 3], u32> = Default::default();
    let mut verts: Vec<DVec3> = Vec::new();
    let mut raw: Vec<[Vec3; 3]> = Vec::new();
    let mut tris: Vec<[u32; 3]> = Vec::new();
    for t in range {
        if !(scene.opaque[t as usize] || alpha_occluders) {
            continue;
        }
        let corners = scene.triangle(t as usize);
        if is_degenerate(corners) {
            stats.degenerate += 1;
            continue;
        }
        let ids = corners.map(|p| {
            let key = [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
            *index.entry(key).or_insert_with(|| {
                verts.push(p.as_dvec3());
                (verts.len() - 1) as u32
            })
        });
        tris.push(ids);
        raw.push(corners);
    }
    stats.triangles = tris.len();
    let mut points = Vec::new();
    let mut parts = Vec::new();
    let mut hulls = Vec::new();
    let mut rest = Vec::new();
    let comps = components(&verts, &tris);
    for k in 0..comps.len() {
        let comp = &comps.triangles[comps.offsets[k] as usize..comps.offsets[k + 1] as usize];
        let comp_tris: Vec<[u32; 3]> = comp.iter().map(|&t| tris[t as usize]).collect();
        if comp_tris.len() <= MAX_SOLID_TRIANGLES
            && let Some(solid) = convex_solid(&verts, &comp_tris)
        {
            let mut hull = DAabb::EMPTY;
            for t in &comp_tris {
                for &v in t {
                    hull.grow(verts[v as usize]);
                }
            }
            push_part(
                &mut points,
                &mut parts,
                object,
                &solid,
                PartKind::Solid {
                    hull: hulls.len() as u32,
                },
                0.0,
                0.0,
            );
            hulls.push(hull);
            stats.solids += 1;
            continue;
        }
        rest.extend(comp.iter().map(|&t| raw[t as usize]));
    }
    (points, parts, hulls, stats, rest)
}

fn push_part(
    points: &mut Vec<DVec3>,
    parts: &mut Vec<OccluderPart>,
    object: u32,
    pts: &[DVec3],
    kind: PartKind,
    deviation: f64,
    inradius: f64,
) {
    let start = points.len() as u32;
    let mut bounds = DAabb::EMPTY;
    for &p in pts {
        bounds.grow(p);
    }
    points.extend_from_slice(pts);
    parts.push(OccluderPart {
        start,
        end: points.len() as u32,
        bounds,
        object,
        kind,
        deviation,
        inradius,
        card: false,
    });
}

/// Distance from the vertex centroid of a convex polygon to its nearest edge line (0 when it
/// has no edge of positive length); the sampler shrinks by it too.
pub(crate) fn polygon_inradius(pts: &[DVec3]) -> f64 {
    let c = pts.iter().copied().sum::<DVec3>() / pts.len() as f64;
    let mut r = f64::INFINITY;
    for i in 0..pts.len() {
        let (a, b) = (pts[i], pts[(i + 1) % pts.len()]);
        let e = b - a;
        let l = e.length();
        if l > 0.0 {
            r = r.min((c - a).cross(e).length() / l);
        }
    }
    if r.is_finite() { r } else { 0.0 }
}

/// Connected components of triangles sharing a vertex, in the order of their first triangle,
/// each listing its triangles in increasing order: component `k` is
/// `triangles[offsets[k]..offsets[k + 1]]` (flat arrays: a forest has millions of one-triangle
/// components).
struct Components {
    offsets: Vec<u32>,
    triangles: Vec<u32>,
}

impl Components {
    fn len(&self) -> usize {
        self.offsets.len() - 1
    }
}

fn components(verts: &[DVec3], tris: &[[u32; 3]]) -> Components {
    let mut parent: Vec<u32> = (0..verts.len() as u32).collect();
    fn find(p: &mut [u32], mut x: u32) -> u32 {
        while p[x as usize] != x {
            p[x as usize] = p[p[x as usize] as usize];
            x = p[x as usize];
        }
        x
    }
    for t in tris {
        let a = find(&mut parent, t[0]);
        for &v in &t[1..] {
            let b = find(&mut parent, v);
            if a != b {
                parent[b as usize] = a;
            }
        }
    }
    // Component ids by first appearance (reusing `parent`'s roots as the key), then a
    // counting sort of the triangles by component (stable: increasing order within each).
    let mut id_of_root = vec![u32::MAX; verts.len()];
    let mut tri_comp = Vec::with_capacity(tris.len());
    let mut counts: Vec<u32> = Vec::new();
    for t in tris {
        let r = find(&mut parent, t[0]) as usize;
        if id_of_root[r] == u32::MAX {
            id_of_root[r] = counts.len() as u32;
            counts.push(0);
        }
        let c = id_of_root[r];
        counts[c as usize] += 1;
        tri_comp.push(c);
    }
    drop(parent);
    drop(id_of_root);
    let mut offsets = Vec::with_capacity(counts.len() + 1);
    offsets.push(0u32);
    for c in &counts {
        offsets.push(offsets.last().expect("non-empty") + c);
    }
    let mut next: Vec<u32> = offsets[..counts.len()].to_vec();
    let mut triangles = vec![0u32; tris.len()];
    for (i, &c) in tri_comp.iter().enumerate() {
        triangles[next[c as usize] as usize] = i as u32;
        next[c as usize] += 1;
    }
    Components { offsets, triangles }
}

/// When the triangles form a closed, outward-oriented convex solid, its vertices shrunk toward
/// their centroid just enough that their convex hull lies inside the solid.
fn convex_solid(verts: &[DVec3], tris: &[[u32; 3]]) -> Option<Vec<DVec3>> {
    if tris.len() < 4 {
        return None;
    }
    // Closed 2-manifold: every directed edge once, its reverse once.
    let mut edges: HashMap<(u32, u32), u32> = HashMap::with_capacity(tris.len() * 3);
    for t in tris {
        for k in 0..3 {
            let e = (t[k], t[(k + 1) % 3]);
            *edges.entry(e).or_insert(0) += 1;
        }
    }
    for (&(a, b), &n) in &edges {
        if n != 1 || edges.get(&(b, a)) != Some(&1) {
            return None;
        }
    }
    let mut ids: Vec<u32> = tris.iter().flatten().copied().collect();
    ids.sort_unstable();
    ids.dedup();
    let pts: Vec<DVec3> = ids.iter().map(|&i| verts[i as usize]).collect();
    let c = pts.iter().copied().sum::<DVec3>() / pts.len() as f64;
    let size = pts.iter().fold(DAabb::EMPTY, |mut b, &p| {
        b.grow(p);
        b
    });
    let extent = (size.max - size.min).max_element();
    let scale = extent.max(size.max.abs().max(size.min.abs()).max_element());
    let tol = 1e-5 * extent + 4.0 * f32::EPSILON as f64 * scale;
    let mut dev: f64 = 0.0;
    let mut rho = f64::INFINITY;
    let mut signed_volume = 0.0;
    for t in tris {
        let (a, b, cc) = (
            verts[t[0] as usize],
            verts[t[1] as usize],
            verts[t[2] as usize],
        );
        signed_volume += a.dot(b.cross(cc));
        let n = (b - a).cross(cc - a);
        let len = n.length();
        if len == 0.0 {
            return None;
        }
        let n = n / len;
        let d = n.dot(a);
        for &p in &pts {
            dev = dev.max(n.dot(p) - d);
        }
        rho = rho.min(d - n.dot(c));
    }
    // Outward orientation (positive volume), convex within tolerance, a real interior.
    if signed_volume <= 0.0 || dev > tol || rho <= 8.0 * dev.max(0.0) || rho <= 0.0 {
        return None;
    }
    // Hull ⊂ solid ⊕ B(k·dev); scaling about c by (1 − k·dev/ρ) brings it inside (B(c, ρ) lies
    // in the solid). k = 3 covers the corner amplification of boxes and most polytopes.
    let shrink = if dev > 0.0 { 3.0 * dev / rho } else { 0.0 };
    Some(pts.iter().map(|&p| c + (p - c) * (1.0 - shrink)).collect())
}

/// A merged convex polygon.
#[derive(Clone, Debug)]
pub struct MergedPolygon {
    /// Indices of the polygon's vertices, in order around it, into the `verts` given to
    /// [`merge_coplanar`].
    pub verts: Vec<u32>,
    /// Unit normal of the fitted plane.
    pub normal: DVec3,
    /// The largest distance of a vertex from the fitted plane (see [`OccluderPart::deviation`]).
    pub deviation: f64,
    /// The distance from the vertex centroid to the nearest edge (see
    /// [`OccluderPart::inradius`]).
    pub inradius: f64,
}

/// The unused coplanar triangles edge-connected to `seed`, and their boundary as one loop
/// (collinear vertices dropped), when that boundary is a single convex loop.
fn convex_region(
    seed: usize,
    tris: &[[u32; 3]],
    by_edge: &HashMap<(u32, u32), usize>,
    used: &[bool],
    coplanar: &impl Fn(usize) -> bool,
    turn: &impl Fn(u32, u32, u32) -> bool,
) -> Option<(Vec<u32>, Vec<usize>)> {
    const MAX_REGION: usize = 4096;
    let mut region = vec![seed];
    let mut seen: std::collections::HashSet<usize> = [seed].into_iter().collect();
    let mut k = 0;
    while k < region.len() {
        let t = tris[region[k]];
        k += 1;
        for e in 0..3 {
            if let Some(&o) = by_edge.get(&(t[(e + 1) % 3], t[e]))
                && !used[o]
                && !seen.contains(&o)
                && coplanar(o)
            {
                if region.len() >= MAX_REGION {
                    return None;
                }
                seen.insert(o);
                region.push(o);
            }
        }
    }
    if region.len() < 2 {
        return None;
    }
    // Boundary: directed edges whose reverse is not in the region; must chain into one loop.
    let in_region = |a: u32, b: u32| by_edge.get(&(a, b)).is_some_and(|t| seen.contains(t));
    let mut next: HashMap<u32, u32> = HashMap::new();
    for &t in &region {
        let tr = tris[t];
        for e in 0..3 {
            let (a, b) = (tr[e], tr[(e + 1) % 3]);
            if !in_region(b, a) && next.insert(a, b).is_some() {
                return None; // a vertex with two outgoing boundary edges: not a simple loop
            }
        }
    }
    // The smallest vertex id starts the loop: a hash map's order differs from run to run,
    // and the polygon's first vertex sets the rounding of what is computed from it.
    let start = *next.keys().min()?;
    let mut loop_verts = vec![start];
    let mut v = next[&start];
    while v != start {
        if loop_verts.len() > next.len() {
            return None;
        }
        loop_verts.push(v);
        v = *next.get(&v)?;
    }
    if loop_verts.len() != next.len() {
        return None; // several loops: holes or separate pieces
    }
    // Convex, with collinear vertices dropped.
    let m = loop_verts.len();
    let mut out = Vec::with_capacity(m);
    for i in 0..m {
        let (a, b, c) = (
            loop_verts[(i + m - 1) % m],
            loop_verts[i],
            loop_verts[(i + 1) % m],
        );
        if !turn(a, b, c) {
            return None;
        }
        if !turn(c, b, a) {
            out.push(b); // a real corner (not collinear)
        }
    }
    (out.len() >= 3).then_some((out, region))
}

/// Whether the closed polygon `poly` turns left at every vertex (round `n`) and once round in
/// all: the exterior angles add up to one full turn, so it is convex and simple.
fn winds_once(poly: &[u32], verts: &[DVec3], n: DVec3) -> bool {
    let m = poly.len();
    let mut total = 0.0;
    for i in 0..m {
        let (a, b, c) = (
            verts[poly[(i + m - 1) % m] as usize],
            verts[poly[i] as usize],
            verts[poly[(i + 1) % m] as usize],
        );
        let (u, v) = (b - a, c - b);
        let angle = u.cross(v).dot(n).atan2(u.dot(v));
        if angle < -1e-9 {
            return false;
        }
        total += angle;
    }
    (total - std::f64::consts::TAU).abs() < 1e-6
}

/// Triangles of earlier pieces one piece may grow through (bounds the work on large flat
/// regions with holes).
const MAX_REUSED: usize = 256;

/// Greedy merge of edge-adjacent coplanar triangles into convex polygons; every triangle is in
/// at least one polygon, and polygons may overlap.
pub fn merge_coplanar(verts: &[DVec3], tris: &[[u32; 3]]) -> Vec<MergedPolygon> {
    let mut by_edge: HashMap<(u32, u32), usize> = HashMap::with_capacity(tris.len() * 3);
    for (i, t) in tris.iter().enumerate() {
        for k in 0..3 {
            by_edge.insert((t[k], t[(k + 1) % 3]), i);
        }
    }
    let normal = |t: &[u32; 3]| {
        let (a, b, c) = (
            verts[t[0] as usize],
            verts[t[1] as usize],
            verts[t[2] as usize],
        );
        (b - a).cross(c - a)
    };
    let mut order: Vec<usize> = (0..tris.len()).collect();
    let areas: Vec<f64> = tris.iter().map(|t| normal(t).length()).collect();
    order.sort_by(|&a, &b| areas[b].total_cmp(&areas[a]));
    let mut used = vec![false; tris.len()];
    let mut out = Vec::new();
    for &seed in &order {
        if used[seed] {
            continue;
        }
        used[seed] = true;
        let n = normal(&tris[seed]).normalize();
        let p0 = verts[tris[seed][0] as usize];
        let d = n.dot(p0);
        let scale = p0.abs().max_element().max(areas[seed].sqrt());
        let plane_tol = 4.0 * f32::EPSILON as f64 * scale;
        let mut poly: Vec<u32> = tris[seed].to_vec();
        // A left turn or a straight continuation; a reversal (the boundary folding back on
        // itself, as at a T-junction's slit) is not a turn a convex polygon makes.
        let turn = |a: u32, b: u32, c: u32| {
            let (a, b, c) = (verts[a as usize], verts[b as usize], verts[c as usize]);
            let t = (b - a).cross(c - b).dot(n);
            let m = (b - a).length() * (c - b).length();
            t > 1e-9 * m || (t >= -1e-9 * m && (b - a).dot(c - b) > 0.0)
        };
        let coplanar = |t: usize| {
            let n2 = normal(&tris[t]).normalize();
            n2.dot(n) >= 1.0 - 1e-9
                && tris[t]
                    .iter()
                    .all(|&v| (n.dot(verts[v as usize]) - d).abs() <= plane_tol)
        };
        // The whole coplanar region first: when its boundary is one convex loop (a wall cut
        // into a grid of quads), it is one polygon, whatever order a greedy merge would take.
        if let Some((loop_verts, region)) =
            convex_region(seed, tris, &by_edge, &used, &coplanar, &turn)
        {
            for t in region {
                used[t] = true;
            }
            poly = loop_verts;
        }
        // Growth may cross triangles that earlier pieces already cover: pieces then overlap
        // instead of abutting (an abutting seam is a crack of a pixel or two in every
        // Projection, since views of two occluders never add up).
        let mut reused = 0usize;
        let mut changed = true;
        while changed {
            changed = false;
            let mut e = 0;
            while e < poly.len() {
                let len = poly.len();
                let (p, q) = (poly[e], poly[(e + 1) % len]);
                if let Some(&t2) = by_edge.get(&(q, p))
                    && (!used[t2] || reused < MAX_REUSED)
                {
                    let tri = tris[t2];
                    let r = tri
                        .iter()
                        .copied()
                        .find(|&v| v != p && v != q)
                        .unwrap_or(tri[0]);
                    let n2 = normal(&tri).normalize();
                    let coplanar = n2.dot(n) >= 1.0 - 1e-9
                        && (n.dot(verts[r as usize]) - d).abs() <= plane_tol;
                    let prev = poly[(e + len - 1) % len];
                    let next = poly[(e + 2) % len];
                    if coplanar
                        && !poly.contains(&r)
                        && turn(prev, p, r)
                        && turn(p, r, q)
                        && turn(r, q, next)
                    {
                        poly.insert(e + 1, r);
                        reused += used[t2] as usize;
                        used[t2] = true;
                        changed = true;
                        continue;
                    }
                }
                e += 1;
            }
        }
        if !winds_once(&poly, verts, n) {
            // Never happens with the checks above; a part must be convex, so fall back to the
            // seed triangle (the others merged into it are lost as occluders: conservative).
            debug_assert!(false, "merged polygon is not convex: {poly:?}");
            poly = tris[seed].to_vec();
        }
        let pts: Vec<DVec3> = poly.iter().map(|&i| verts[i as usize]).collect();
        let deviation = if poly.len() == 3 {
            0.0
        } else {
            pts.iter()
                .map(|&p| (n.dot(p) - d).abs())
                .fold(0.0, f64::max)
        };
        let c = pts.iter().copied().sum::<DVec3>() / pts.len() as f64;
        let inradius = (0..pts.len())
            .map(|k| {
                let (a, b) = (pts[k], pts[(k + 1) % pts.len()]);
                let e = b - a;
                (c - a).cross(e).length() / e.length()
            })
            .fold(f64::INFINITY, f64::min);
        out.push(MergedPolygon {
            verts: poly,
            normal: n,
            deviation,
            inradius,
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use std::path::Path;

    /// A part's size is most of the occluder tables' memory (7.9 M parts on the paper-size
    /// forest): it was 144 bytes with a solid's hull inline.
    #[test]
    fn a_part_takes_at_most_112_bytes() {
        assert!(std::mem::size_of::<OccluderPart>() <= 112);
    }

    #[test]
    fn weld_numbers_positions_in_order_of_first_occurrence() {
        // Corners drawn from few positions, so most repeat; -0.0 and 0.0 differ in their
        // bits and stay apart, as they did in the hash map this replaced.
        let mut state = 7u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) as usize
        };
        let pool = [
            Vec3::ZERO,
            Vec3::new(-0.0, 0.0, 0.0),
            Vec3::new(1.0, 2.0, 3.0),
            Vec3::new(1.0, 2.0, 3.0000002),
            Vec3::new(-4.5, 1e30, 7.0),
            Vec3::new(3.0, 2.0, 1.0),
        ];
        for n in [0usize, 1, 2, 17, 5000] {
            let corners: Vec<Vec3> = (0..n)
                .map(|i| {
                    if i % 3 == 0 {
                        pool[next() % pool.len()]
                    } else {
                        Vec3::new((next() % 40) as f32, 0.5, -((next() % 3) as f32))
                    }
                })
                .collect();
            let (ids, verts) = weld(&corners);
            // The hash map's numbering, in order.
            let mut index: HashMap<[u32; 3], u32> = HashMap::new();
            let mut want_verts = Vec::new();
            let want: Vec<u32> = corners
                .iter()
                .map(|p| {
                    *index
                        .entry([p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
                        .or_insert_with(|| {
                            want_verts.push(p.as_dvec3());
                            want_verts.len() as u32 - 1
                        })
                })
                .collect();
            assert_eq!(ids, want, "{n} corners");
            assert_eq!(verts, want_verts, "{n} corners");
            if n > 100 {
                assert!(verts.len() < n / 2, "the test must repeat positions");
            }
        }
    }

    fn quad_grid(n: usize) -> Vec<[Vec3; 3]> {
        // An n×n grid of quads on z = 5, each split into two triangles.
        let mut tris = Vec::new();
        for i in 0..n {
            for j in 0..n {
                let p = |a: usize, b: usize| Vec3::new(a as f32, b as f32, 5.0);
                tris.push([p(i, j), p(i + 1, j), p(i + 1, j + 1)]);
                tris.push([p(i, j), p(i + 1, j + 1), p(i, j + 1)]);
            }
        }
        tris
    }

    #[test]
    fn a_flat_grid_merges_into_one_convex_polygon() {
        let scene = Scene::from_objects(Path::new("t"), vec![("wall".into(), quad_grid(4), true)]);
        let occ = prepare(&scene, &[true], false);
        assert_eq!(occ.parts.len(), 1, "{:?}", occ.parts.len());
        let b = occ.parts[0].bounds;
        assert_eq!((b.min.x, b.max.x, b.min.y, b.max.y), (0.0, 4.0, 0.0, 4.0));
        assert_eq!(occ.parts[0].deviation, 0.0);
    }

    /// The parts do not depend on the run: the merged loop once started at whichever
    /// vertex a hash map listed first, which differs from map to map (zdm2's PVS changed from
    /// run to run in a few cells).
    #[test]
    fn a_merge_gives_the_same_polygon_every_time() {
        let scene = Scene::from_objects(Path::new("t"), vec![("wall".into(), quad_grid(4), true)]);
        let first = prepare(&scene, &[true], false);
        for _ in 0..20 {
            let again = prepare(&scene, &[true], false);
            assert_eq!(again.points, first.points);
            assert_eq!(again.parts, first.parts);
        }
    }

    #[test]
    fn an_l_shape_is_split_into_convex_pieces() {
        let mut tris = quad_grid(2);
        tris.remove(7);
        tris.remove(6); // drop quad (1,1): an L of three quads
        let scene = Scene::from_objects(Path::new("t"), vec![("l".into(), tris, true)]);
        let occ = prepare(&scene, &[true], false);
        assert!(occ.parts.len() >= 2);
        // Every polygon is convex: all turns left.
        for k in 0..occ.parts.len() {
            let p = occ.part_points(k);
            for i in 0..p.len() {
                let (a, b, c) = (p[i], p[(i + 1) % p.len()], p[(i + 2) % p.len()]);
                assert!((b - a).cross(c - b).z >= -1e-12);
            }
        }
    }

    /// A wall with a window, as zdm2's `slot1495` (12 triangles at x = −302): no part may
    /// cover the window (an L-shaped "convex" part covered it and culled what was seen
    /// through it).
    #[test]
    fn a_wall_with_a_window_never_gets_a_part_over_the_window() {
        let t = |a: [f32; 2], b: [f32; 2], c: [f32; 2]| {
            [a, b, c].map(|p| Vec3::new(-302.0, p[0], p[1]))
        };
        let tris = vec![
            t([208.0, -96.0], [200.0, -80.0], [200.0, -96.0]),
            t([208.0, -96.0], [208.0, -80.0], [200.0, -80.0]),
            t([176.0, -96.0], [176.0, -104.0], [184.0, -104.0]),
            t([192.0, -104.0], [208.0, -104.0], [176.0, -96.0]),
            t([184.0, -104.0], [192.0, -104.0], [176.0, -96.0]),
            t([200.0, -96.0], [176.0, -96.0], [208.0, -104.0]),
            t([208.0, -104.0], [208.0, -96.0], [200.0, -96.0]),
            t([200.0, -96.0], [176.0, -92.0], [176.0, -96.0]),
            t([200.0, -96.0], [200.0, -92.0], [176.0, -92.0]),
            t([176.0, -50.0], [176.0, -80.0], [200.0, -80.0]),
            t([200.0, -80.0], [208.0, -80.0], [176.0, -50.0]),
            t([208.0, -80.0], [208.0, -50.0], [176.0, -50.0]),
        ];
        let scene = Scene::from_objects(Path::new("t"), vec![("wall".into(), tris, true)]);
        let occ = prepare(&scene, &[true], false);
        // The window: y in (176, 200), z in (-92, -80).
        for k in 0..occ.parts.len() {
            let p = occ.part_points(k);
            // Convex: every turn the same way round the normal.
            if let PartKind::Polygon { normal } = occ.parts[k].kind {
                for i in 0..p.len() {
                    let (a, b, c) = (p[i], p[(i + 1) % p.len()], p[(i + 2) % p.len()]);
                    assert!(
                        (b - a).cross(c - b).dot(normal) >= -1e-9,
                        "part {k} is not convex: {p:?}"
                    );
                }
            }
            let inside = |y: f64, z: f64| {
                (0..p.len()).all(|i| {
                    let (a, b) = (p[i], p[(i + 1) % p.len()]);
                    let (ey, ez) = (b.y - a.y, b.z - a.z);
                    let s = ey * (z - a.z) - ez * (y - a.y);
                    s >= 0.0
                }) || (0..p.len()).all(|i| {
                    let (a, b) = (p[i], p[(i + 1) % p.len()]);
                    let (ey, ez) = (b.y - a.y, b.z - a.z);
                    ey * (z - a.z) - ez * (y - a.y) <= 0.0
                })
            };
            assert!(!inside(188.0, -86.0), "part {k} covers the window: {p:?}");
        }
    }

    #[test]
    fn a_box_becomes_one_solid_and_an_open_box_does_not() {
        let b = crate::geom::box_triangles(Vec3::ZERO, Vec3::new(2.0, 3.0, 4.0));
        let mut open = b.clone();
        open.truncate(10);
        let scene = Scene::from_objects(
            Path::new("t"),
            vec![("box".into(), b, true), ("open".into(), open, true)],
        );
        let occ = prepare(&scene, &[true, true], false);
        let solids: Vec<_> = occ
            .parts
            .iter()
            .filter(|p| matches!(p.kind, PartKind::Solid { .. }))
            .collect();
        assert_eq!(solids.len(), 1);
        assert_eq!(solids[0].object, 0);
        assert_eq!(solids[0].end - solids[0].start, 8);
        assert_eq!(occ.stats.solids, 1);
        assert!(occ.parts.iter().filter(|p| p.object == 1).count() >= 4);
    }

    #[test]
    fn non_opaque_triangles_are_not_occluders_unless_asked() {
        let scene = Scene::from_objects(Path::new("t"), vec![("leaf".into(), quad_grid(1), false)]);
        assert!(prepare(&scene, &[true], false).parts.is_empty());
        assert_eq!(prepare(&scene, &[true], true).parts.len(), 1);
        assert!(prepare(&scene, &[false], true).parts.is_empty());
    }
}
