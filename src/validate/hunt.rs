//! `umbrasweep validate --hunt`: the ray budget spent on the objects a PVS culls.
//!
//! The plain sampling ([`sample_cell`](super::sample_cell)) measures the visible set and
//! finds a false cull only if it happens to find the culled object among all the others; on a
//! big scene most of the budget goes to objects the PVS keeps anyway. The hunt instead takes,
//! per cell, the objects with area that are *not* in the cell's PVS (the culled objects) and
//! splits the cell's budget evenly between them: `rays_per_culled_object(rays, culled)` =
//! `rays / culled`, at least 1. Culled object number `k` (ascending by id) of a cell gets the
//! cell's global ray indices `[k·m, (k+1)·m)`, `m` being that count.
//!
//! Every fresh hunting ray starts strictly inside the cell (3/8 uniform, 2/8 on a face, 1/8 near an
//! edge, 2/8 near a corner) and is aimed at a point of the culled object: 3/8 on its surface
//! (area-weighted), 1/8 uniform inside its bounds, 3/8 near an edge and 1/8 near a vertex of
//! one of its triangles (picked by count, so that small triangles' edges count: a thin gap
//! shows an object near its silhouette). The ray is traced only as far as it can meet the
//! object (to where it leaves the object's slightly padded bounds); the object is seen when
//! one of the triangles the ray reaches, see-through ones in front of the first blocking one
//! included, is the object's, exactly as in the plain sampling (see-through triangles block
//! when the PVS was baked with `alpha_occluders`). Such a ray proves a false cull; so does a
//! ray aimed at one culled object that meets another culled object of the cell first on its
//! way (rays are shared the way the plain sampling's uniform rays are).
//!
//! **Near misses.** Objects seen only through a row of gaps (a trunk's foot under a canopy)
//! are reached by few such pairs, but a pair whose ray passes some of the gaps gets farther
//! along its line before a triangle stops it. So each chunk keeps its best near miss (the
//! pair whose first hit lies farthest along the line to its target, as a share of it) and,
//! after its first [`FRESH_FIRST`] rays, aims three rays in four at pairs near it
//! ([`near_pair`]: the origin moved by up to a tenth of the cell, the target by up to a tenth
//! of the object, log-uniform down to 10⁻⁴ of those). A ray is a ray: what any of them
//! reaches proves a false cull as before. On the coarse forest's 1×1×1 cell, 20 M rays aimed
//! at a PVS that culls at least 159 visible objects found 119 of them, against 85 with fresh
//! pairs only (5 M rays: 85 against 59).
//!
//! Each object's budget is cut into chunks of [`CHUNK`] rays with their own random stream,
//! seeded from `(seed, cell, object, chunk)`. The chunks are traced in waves (chunk 0 of
//! every pair, then chunks 1–2, 3–6, … doubling), all cells and objects of a wave in parallel;
//! a chunk stops at its first ray that sees its object, and an object seen in one wave (by its
//! own rays or another object's) gets no further waves. Its witness is the seeing ray with the
//! smallest index among all rays cast, so the result (rays cast included) does not depend on
//! the number of threads.

use super::sample::{CHUNK, Witness, chunk_rng, clamp_inside, sphere_direction, unit};
use super::trace::{RawHit, SceneRays};
use crate::geom::Aabb;
use crate::scene::Scene;
use glam::{DVec3, Vec3};
use rand::RngCore;
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;
use std::collections::BTreeMap;

/// [`Witness::phase`] of a ray cast by `--hunt`.
pub const HUNT_PHASE: u32 = 7;

/// Hunting streams are `chunk_rng(seed, cell, HUNT_STREAM + object, chunk)`: the plain
/// phases use streams 0–6 and object ids are below 2³².
const HUNT_STREAM: u64 = 1 << 32;

/// Rays `--hunt` casts at each culled object of a cell whose budget is `rays` and which culls
/// `culled` objects with area: `rays / culled`, at least 1 (0 when nothing is culled).
pub fn rays_per_culled_object(rays: u64, culled: usize) -> u64 {
    if culled == 0 {
        0
    } else {
        (rays / culled as u64).max(1)
    }
}

/// One cell to hunt in.
pub(crate) struct HuntCell {
    /// The cell.
    pub cell: Aabb,
    /// Selects the cell's random streams (its position in the PVS).
    pub cell_index: u64,
    /// The culled objects with area, ascending.
    pub culled: Vec<u32>,
    /// Objects, ascending and none of them in `culled`, whose sighting by any ray is
    /// recorded (with its witness) but which get no rays of their own (position
    /// `culled.len() + k` for the `k`-th). `--confirm-rays` aims at the PVS objects in doubt
    /// and lists the culled objects here, so that a confirming ray that meets a culled object
    /// first proves a false cull. Empty for `--hunt`.
    pub bystanders: Vec<u32>,
}

impl HuntCell {
    /// The position of `object` in [`Self::culled`] followed by [`Self::bystanders`].
    fn position(&self, object: u32) -> Option<u32> {
        if let Ok(pos) = self.culled.binary_search(&object) {
            return Some(pos as u32);
        }
        let k = self.bystanders.binary_search(&object).ok()?;
        Some((self.culled.len() + k) as u32)
    }

    /// The object at `pos` ([`Self::position`]).
    fn object_at(&self, pos: u32) -> u32 {
        let pos = pos as usize;
        match self.culled.get(pos) {
            Some(&o) => o,
            None => self.bystanders[pos - self.culled.len()],
        }
    }
}

/// What the hunt found in one cell.
#[derive(Debug, Default)]
pub(crate) struct HuntResult {
    /// [`rays_per_culled_object`] of the cell.
    pub rays_per_object: u64,
    /// Culled objects (and bystanders) some ray saw, ascending, each with its first ray.
    pub seen: Vec<(u32, Witness)>,
    /// Rays actually cast (chunks stop at their first ray that sees the object, and seen
    /// objects get no further waves).
    pub rays_cast: u64,
}

/// A (cell, culled object) pair.
#[derive(Clone, Copy)]
struct Pair {
    cell: u32,
    /// Position of the object in the cell's culled list.
    pos: u32,
    /// Chunks of the object's budget.
    chunks: u64,
}

/// A culled object of the cell seen by a ray of a chunk: the chunk's own object, or another
/// culled object the ray met first on its way. One per object and chunk, its first ray.
#[derive(Clone, Copy, Debug)]
struct Seen {
    /// Position of the object seen in the cell's culled list.
    pos: u32,
    /// Index of the ray within the budget of the chunk's own object.
    ray: u64,
    origin: Vec3,
    direction: Vec3,
    /// The scene triangle hit (the object's nearest along the ray).
    triangle: u32,
    t: f32,
}

/// The chunks of wave `w`: `[2^w − 1, 2^(w+1) − 1)`.
fn wave(w: u32) -> (u64, u64) {
    let lo = 1u64.checked_shl(w).map_or(u64::MAX, |x| x - 1);
    let hi = 1u64.checked_shl(w + 1).map_or(u64::MAX, |x| x - 1);
    (lo, hi)
}

/// Per-worker scratch memory.
#[derive(Default)]
struct Scratch {
    hits: Vec<RawHit>,
    /// Culled objects among one ray's hits: (position, t, triangle).
    culled_hits: Vec<(u32, f32, u32)>,
    /// Positions already seen in the current chunk.
    noted: std::collections::HashSet<u32>,
}

/// Hunts in every cell of `cells` with `rays` rays per cell; one result per cell, in order.
/// `progress` advances by the rays of each chunk traced.
///
/// A culled object is seen when a ray aimed at it reaches it, or when a ray aimed at another
/// culled object of the cell meets it first; its witness is the seeing ray with the smallest
/// global index among all rays cast. Seen objects get no further waves.
pub(crate) fn hunt_cells(
    index: &SceneRays,
    scene: &Scene,
    cells: &[HuntCell],
    rays: u64,
    seed: u64,
    alpha_blocks: bool,
    progress: Option<&super::check::ProgressFn>,
) -> Vec<HuntResult> {
    let mut results: Vec<HuntResult> = cells
        .iter()
        .map(|c| HuntResult {
            rays_per_object: rays_per_culled_object(rays, c.culled.len()),
            ..HuntResult::default()
        })
        .collect();
    // Per cell, by culled position: the best witness so far (global ray index, sighting).
    let mut best: Vec<BTreeMap<u32, (u64, Seen)>> = vec![BTreeMap::new(); cells.len()];
    let mut open: Vec<Pair> = Vec::new();
    for (ci, c) in cells.iter().enumerate() {
        let m = results[ci].rays_per_object;
        for pos in 0..c.culled.len() {
            open.push(Pair {
                cell: ci as u32,
                pos: pos as u32,
                chunks: m.div_ceil(CHUNK),
            });
        }
    }
    let mut w = 0u32;
    while !open.is_empty() {
        let (lo, hi) = wave(w);
        w += 1;
        open.retain(|p| p.chunks > lo);
        // One task per chunk of the wave: (pair, chunk).
        let tasks: Vec<(u32, u64)> = open
            .iter()
            .enumerate()
            .flat_map(|(i, p)| (lo..hi.min(p.chunks)).map(move |j| (i as u32, j)))
            .collect();
        let open_ref = &open;
        let seen: Vec<Vec<Seen>> = tasks
            .par_iter()
            .map_init(Scratch::default, |scratch, &(pi, j)| {
                let p = open_ref[pi as usize];
                let c = &cells[p.cell as usize];
                let m = rays_per_culled_object(rays, c.culled.len());
                let begin = j * CHUNK;
                let end = (begin + CHUNK).min(m);
                let object = c.culled[p.pos as usize];
                let rng = chunk_rng(seed, c.cell_index, HUNT_STREAM + u64::from(object), j);
                let out = hunt_chunk(index, c, p.pos, rng, begin..end, alpha_blocks, scratch);
                if let Some(pb) = progress {
                    pb(super::check::Progress::Advance(end - begin));
                }
                out
            })
            .collect();

        for (&(pi, j), found) in tasks.iter().zip(seen) {
            let p = open[pi as usize];
            let r = &mut results[p.cell as usize];
            let m = r.rays_per_object;
            let end = (j * CHUNK + CHUNK).min(m);
            r.rays_cast += end - j * CHUNK;
            for f in found {
                if f.pos == p.pos {
                    // The chunk stopped at this ray.
                    r.rays_cast -= end - (f.ray + 1);
                }
                let global = u64::from(p.pos) * m + f.ray;
                best[p.cell as usize]
                    .entry(f.pos)
                    .and_modify(|b| {
                        if global < b.0 {
                            *b = (global, f);
                        }
                    })
                    .or_insert((global, f));
            }
        }
        open.retain(|p| !best[p.cell as usize].contains_key(&p.pos));
    }
    for ((r, c), b) in results.iter_mut().zip(cells).zip(best) {
        r.seen = b
            .into_iter()
            .map(|(pos, (global, s))| {
                let witness = Witness {
                    origin: s.origin,
                    direction: s.direction,
                    hit: SceneRays::precise_hit(scene, s.triangle, s.origin, s.direction, s.t),
                    triangle: s.triangle,
                    phase: HUNT_PHASE,
                    ray: global,
                };
                (c.object_at(pos), witness)
            })
            .collect();
        r.seen.sort_unstable_by_key(|e| e.0);
    }
    results
}

/// Traces rays `range` of the budget of culled object `own` (a position in `cell.culled`;
/// the chunk's stream `rng` starts at the range's first ray) until one sees it, and returns
/// every culled object of the cell its rays saw, each with its first ray (in ray order).
fn hunt_chunk(
    index: &SceneRays,
    cell: &HuntCell,
    own: u32,
    mut rng: Pcg64Mcg,
    range: std::ops::Range<u64>,
    alpha_blocks: bool,
    s: &mut Scratch,
) -> Vec<Seen> {
    let object = cell.culled[own as usize];
    let mut out = Vec::new();
    s.noted.clear();
    let start = range.start;
    // The pair whose ray got farthest towards its target so far, for the local search.
    let mut best: Option<NearMiss> = None;
    let sizes = step_sizes(&cell.cell, index, object);
    for ray in range {
        let k = ray - start;
        let pair = match &best {
            Some(b) if k >= FRESH_FIRST && !k.is_multiple_of(4) => {
                near_pair(&mut rng, b, &cell.cell, sizes)
            }
            _ => (
                hunt_origin(&mut rng, &cell.cell),
                hunt_target(&mut rng, index, object),
            ),
        };
        let (origin, direction, tmax) = hunt_ray(&mut rng, pair, index, object);
        let Some(tmax) = tmax else { continue };
        index.trace_raw_until(origin, direction, tmax, alpha_blocks, &mut s.hits);
        // How far along the line to its target the ray got before anything stopped it
        // (1: nothing did).
        let reach = pair.1.distance(origin.as_dvec3());
        let first = s.hits.iter().map(|h| h.t).fold(f32::INFINITY, f32::min);
        let score = if reach > 0.0 {
            (f64::from(first) / reach).min(1.0)
        } else {
            0.0
        };
        if best.as_ref().is_none_or(|b| score > b.score) {
            best = Some(NearMiss {
                origin: origin.as_dvec3(),
                target: pair.1,
                score,
            });
        }
        s.culled_hits.clear();
        for h in &s.hits {
            let m = index.meta(h.slot);
            if let Some(pos) = cell.position(m.object) {
                s.culled_hits.push((pos, h.t, m.triangle));
            }
        }
        // The nearest hit of each object (ties: the lower triangle), whatever the
        // traversal order.
        s.culled_hits
            .sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)).then(a.2.cmp(&b.2)));
        s.culled_hits.dedup_by_key(|e| e.0);
        let mut own_seen = false;
        for &(pos, t, triangle) in &s.culled_hits {
            own_seen |= pos == own;
            if s.noted.insert(pos) {
                out.push(Seen {
                    pos,
                    ray,
                    origin,
                    direction,
                    triangle,
                    t,
                });
            }
        }
        if own_seen {
            break;
        }
    }
    out
}

/// A chunk's best near miss: the (origin, target) pair whose ray got farthest along the line
/// to its target before a triangle stopped it, as a share of that line (`score`).
struct NearMiss {
    origin: DVec3,
    target: DVec3,
    score: f64,
}

/// Rays at the start of every chunk that are all fresh pairs; after them three rays in four
/// are [`near_pair`]s (ray numbers within the chunk not a multiple of 4).
const FRESH_FIRST: u64 = CHUNK / 8;

/// The sizes [`near_pair`] steps by: the largest sides of the cell and of `object`'s bounds.
fn step_sizes(cell: &Aabb, index: &SceneRays, object: u32) -> (f64, f64) {
    (
        cell.size().as_dvec3().max_element(),
        index.object_bounds(object).size().as_dvec3().max_element(),
    )
}

/// A pair near the best near miss `b`: its origin moved by up to a tenth of the cell's size
/// and its target by up to a tenth of the object's (`sizes`, [`step_sizes`]; log-uniform down
/// to 10⁻⁴ of them, in a random direction), the origin kept strictly inside `cell`.
fn near_pair(
    rng: &mut Pcg64Mcg,
    b: &NearMiss,
    cell: &Aabb,
    (cell_size, object_size): (f64, f64),
) -> (Vec3, DVec3) {
    let mut step = |size: f64| sphere_direction(rng) * size * 10f64.powf(-1.0 - 3.0 * unit(rng));
    let origin = clamp_inside(b.origin + step(cell_size), cell);
    let target = b.target + step(object_size);
    (origin, target)
}

/// One hunting ray of the pair (origin strictly inside the cell, target point): the origin,
/// the unit direction, and how far to trace it (`None` when the object's bounds lie wholly
/// behind the origin). A degenerate pair gets a random direction.
fn hunt_ray(
    rng: &mut Pcg64Mcg,
    (origin, target): (Vec3, DVec3),
    index: &SceneRays,
    object: u32,
) -> (Vec3, Vec3, Option<f32>) {
    let o = origin.as_dvec3();
    let dir = target - o;
    let len = dir.length();
    let mut d = if len > 1e-12 * (1.0 + o.abs().max_element()) && len.is_finite() {
        (dir / len).as_vec3()
    } else {
        Vec3::ZERO
    };
    if d == Vec3::ZERO || !d.is_finite() {
        d = sphere_direction(rng).as_vec3();
    }
    (
        origin,
        d,
        exit_distance(&index.object_bounds(object), origin, d),
    )
}

/// Where the ray `origin + t·d` leaves `bounds` padded by 10⁻⁴ of its scale (far above the
/// rounding of the ray/triangle test), a little beyond; `None` when that is behind the
/// origin. Every hit on a triangle inside `bounds` is at most this far.
fn exit_distance(bounds: &Aabb, origin: Vec3, d: Vec3) -> Option<f32> {
    let (lo, hi) = (bounds.min.as_dvec3(), bounds.max.as_dvec3());
    let scale = lo.abs().max(hi.abs()).max_element() + (hi - lo).max_element();
    let pad = 1e-4 * (1.0 + scale);
    let (o, d) = (origin.as_dvec3(), d.as_dvec3());
    let mut t = f64::INFINITY;
    for k in 0..3 {
        if d[k] > 0.0 {
            t = t.min((hi[k] + pad - o[k]) / d[k]);
        } else if d[k] < 0.0 {
            t = t.min((lo[k] - pad - o[k]) / d[k]);
        }
    }
    if t.is_nan() || t < 0.0 {
        return None;
    }
    let t = (t * (1.0 + 1e-6) + pad) as f32;
    Some(if t.is_finite() { t } else { f32::INFINITY })
}

/// Origins of hunting rays, strictly inside the cell: 3/8 uniform, 2/8 on a face (inset by
/// 10⁻⁶ of the cell), 1/8 near an edge and 2/8 near a corner (within 2 % of the cell's size
/// of it on each pinned axis).
fn hunt_origin(rng: &mut Pcg64Mcg, cell: &Aabb) -> Vec3 {
    let (lo, hi, size) = (
        cell.min.as_dvec3(),
        cell.max.as_dvec3(),
        cell.size().as_dvec3(),
    );
    let kind = rng.next_u64() & 7;
    let mut p = lo + size * DVec3::new(unit(rng), unit(rng), unit(rng));
    let mut pin = |axis: usize, high: bool, inset: f64| {
        let d = size[axis] * inset;
        p[axis] = if high { hi[axis] - d } else { lo[axis] + d };
    };
    match kind {
        0..=2 => {}
        3 | 4 => {
            let r = rng.next_u64();
            pin((r % 3) as usize, r & 4 != 0, 1e-6);
        }
        5 => {
            let r = rng.next_u64();
            let free = (r % 3) as usize;
            for (bit, axis) in [(free + 1) % 3, (free + 2) % 3].into_iter().enumerate() {
                pin(axis, r & (4 << bit) != 0, 1e-6 + 0.02 * unit(rng));
            }
        }
        _ => {
            let r = rng.next_u64();
            for axis in 0..3 {
                pin(axis, r & (1 << axis) != 0, 1e-6 + 0.02 * unit(rng));
            }
        }
    }
    clamp_inside(p, cell)
}

/// A barycentric weight for points near an edge: exactly 0 one time in eight, else
/// log-uniform in [10⁻⁶, 10⁻¹].
fn edge_weight(rng: &mut Pcg64Mcg) -> f64 {
    if rng.next_u64() & 7 == 0 {
        0.0
    } else {
        0.1 * 1e-5f64.powf(unit(rng))
    }
}

/// Target points of hunting rays on `object`: 3/8 on its surface (area-weighted), 1/8
/// uniform in its bounds, 3/8 near an edge and 1/8 near a vertex of one of its triangles
/// (picked by count).
fn hunt_target(rng: &mut Pcg64Mcg, index: &SceneRays, object: u32) -> DVec3 {
    let kind = rng.next_u64() & 7;
    let n = index.object_triangle_count(object);
    let bounds = index.object_bounds(object);
    if kind == 3 || n == 0 {
        let (lo, size) = (bounds.min.as_dvec3(), bounds.size().as_dvec3());
        return lo + size * DVec3::new(unit(rng), unit(rng), unit(rng));
    }
    if kind < 3 {
        let (pick, r1, r2) = (unit(rng), unit(rng), unit(rng));
        return index
            .surface_point(object, pick, r1, r2)
            .unwrap_or_else(|| bounds.center().as_dvec3());
    }
    let i = ((unit(rng) * f64::from(n)) as u32).min(n - 1);
    let tri = index.object_triangle(object, i).map(|p| p.as_dvec3());
    let e = (rng.next_u64() % 3) as usize;
    let (a, b, c) = (tri[e], tri[(e + 1) % 3], tri[(e + 2) % 3]);
    if kind < 7 {
        // Near edge a–b: a point of the edge moved a little towards c.
        let q = a + (b - a) * unit(rng);
        q + (c - q) * edge_weight(rng)
    } else {
        // Near vertex a.
        let (f1, f2) = (edge_weight(rng), edge_weight(rng));
        a + (b - a) * f1 + (c - a) * f2
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::vec3;
    use std::path::Path;

    #[test]
    fn budget_split_is_at_least_one_ray() {
        assert_eq!(rays_per_culled_object(1000, 0), 0);
        assert_eq!(rays_per_culled_object(1000, 3), 333);
        assert_eq!(rays_per_culled_object(2, 5), 1);
    }

    #[test]
    fn waves_double_and_cover_every_chunk() {
        let mut next = 0;
        for w in 0..60 {
            let (lo, hi) = wave(w);
            assert_eq!(lo, next);
            assert_eq!(hi - lo, 1 << w);
            next = hi;
        }
        assert_eq!(wave(63).1, u64::MAX);
    }

    #[test]
    fn hunt_origins_are_strictly_inside_and_reach_the_corners() {
        let cell = Aabb::new(vec3(1.0, 2.0, 3.0), vec3(1.5, 2.001, 40.0));
        let mut rng = chunk_rng(1, 2, HUNT_STREAM, 4);
        let mut corners = [0u32; 8];
        for _ in 0..20_000 {
            let p = hunt_origin(&mut rng, &cell);
            assert!(p.cmpgt(cell.min).all() && p.cmplt(cell.max).all(), "{p:?}");
            let near = (p - cell.min).min(cell.max - p).cmplt(cell.size() * 0.021);
            if near.all() {
                let k = (0..3).fold(0, |k, a| k | (usize::from(p[a] > cell.center()[a]) << a));
                corners[k] += 1;
            }
        }
        // 2/8 of the origins are near a corner, 1/32 near each.
        for c in corners {
            assert!((450..800).contains(&c), "{corners:?}");
        }
    }

    /// The ray index of a scene of one object: the triangle (0, 0, 5), (4, 0, 5), (0, 2, 5).
    fn one_triangle() -> SceneRays {
        let tri = [
            vec3(0.0, 0.0, 5.0),
            vec3(4.0, 0.0, 5.0),
            vec3(0.0, 2.0, 5.0),
        ];
        SceneRays::new(&Scene::from_objects(
            Path::new("mem"),
            vec![("t".into(), vec![tri], true)],
        ))
    }

    #[test]
    fn near_pairs_stay_inside_and_near_the_best() {
        let index = one_triangle();
        // A flat cell, and a best near miss at its corner.
        let cell = Aabb::new(vec3(1.0, 2.0, 3.0), vec3(1.5, 2.001, 4.0));
        let best = NearMiss {
            origin: glam::dvec3(1.5, 2.001, 4.0),
            target: glam::dvec3(1.0, 1.0, 5.0),
            score: 0.5,
        };
        let mut rng = chunk_rng(5, 0, HUNT_STREAM, 0);
        let (mut close_o, mut close_t) = (0, 0);
        for _ in 0..4000 {
            let (o, t) = near_pair(&mut rng, &best, &cell, step_sizes(&cell, &index, 0));
            assert!(o.cmpgt(cell.min).all() && o.cmplt(cell.max).all(), "{o:?}");
            // Steps of at most a tenth of the cell's and the object's sizes (1 and 4).
            assert!(o.as_dvec3().distance(best.origin) <= 0.1 + 1e-6, "{o:?}");
            let dt = t.distance(best.target);
            assert!(dt <= 0.4 + 1e-9, "{t:?}");
            close_o += usize::from(o.as_dvec3().distance(best.origin) < 1e-3);
            close_t += usize::from(dt < 4e-3);
        }
        // Log-uniform steps: about a third of them under a hundredth of the largest.
        assert!((1000..1700).contains(&close_t), "{close_t}");
        assert!(close_o > 1000, "{close_o}");
    }

    #[test]
    fn targets_near_edges_lie_on_the_triangles() {
        let index = one_triangle();
        let mut rng = chunk_rng(3, 0, HUNT_STREAM, 0);
        let (mut near_edge, mut outside) = (0, 0);
        for _ in 0..4000 {
            let p = hunt_target(&mut rng, &index, 0);
            assert!((p.z - 5.0).abs() < 1e-9, "{p:?}");
            assert!(
                p.x >= -1e-9 && p.y >= -1e-9 && p.x <= 4.0 && p.y <= 2.0,
                "{p:?}"
            );
            if p.x / 4.0 + p.y / 2.0 > 1.0 + 1e-9 {
                // Only targets inside the bounds (1/8) may leave the triangle.
                outside += 1;
                continue;
            }
            let edge = p.x.min(p.y).min((1.0 - p.x / 4.0 - p.y / 2.0) * 2.0);
            if edge < 1e-3 {
                near_edge += 1;
            }
        }
        // Targets near edges and vertices are half of all, most within 10⁻³ of an edge.
        assert!(near_edge > 800, "{near_edge}");
        assert!(outside < 400, "{outside}");
    }

    #[test]
    fn exit_distance_bounds_the_object() {
        let b = Aabb::new(vec3(-1.0, -1.0, 4.0), vec3(1.0, 1.0, 6.0));
        let t = exit_distance(&b, Vec3::ZERO, Vec3::Z).unwrap();
        assert!((6.0..6.01).contains(&t), "{t}");
        assert_eq!(exit_distance(&b, Vec3::ZERO, -Vec3::Z), None);
        // From inside the bounds.
        let t = exit_distance(&b, vec3(0.0, 0.0, 5.0), Vec3::X).unwrap();
        assert!((1.0..1.01).contains(&t), "{t}");
    }
}
