//! Ray sampling of one cell's visible set ([`sample_cell`]): the ray budget, its phases, the
//! per-chunk random streams and the deterministic merge of what the chunks found.
//!
//! The budget of `N` rays is cut at tenths (`b(k) = N·k/10`):
//! * phase 0, rays `[0, b2)`: origins uniform in the cell, directions uniform on the sphere;
//! * phase 1, rays `[b2, b5)`: origins uniform in the cell, aimed at a random point of a random
//!   object (each object equally likely; half the targets uniform inside the object's bounds,
//!   half on its surface, area-weighted);
//! * phases 2–6, rays `[b5, b6)`, …, `[b9, b10)`: targeted rounds, aimed like phase 1 but only
//!   at the objects no earlier phase has found (decided from the merged result of all earlier
//!   phases). Half of their origins are uniform in the cell, a quarter on its faces and a
//!   quarter near its corners (always strictly inside), to find objects seen through a small
//!   gap or from one corner of the cell. When every object that has area is found, the
//!   remaining rays are not cast.
//!
//! Each phase is split into chunks of [`CHUNK`] rays with their own random stream, seeded from
//! `(seed, cell, phase, chunk)`; chunk results are merged in chunk order and the witness of an
//! object is the ray with the smallest `(phase, chunk, index)`, i.e. the smallest global ray
//! index. The result is therefore the same whatever the number of threads.

use super::trace::{RawHit, SceneRays};
use crate::geom::Aabb;
use crate::scene::Scene;
use glam::{DVec3, Vec3};
use rand::RngCore;
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Rays per chunk: the unit of parallel work and of random streams.
pub const CHUNK: u64 = 4096;

/// The ray that proves an object visible: its first hit (or a see-through triangle before
/// the first blocking hit) is on the object.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Witness {
    /// Ray origin, strictly inside the cell.
    pub origin: Vec3,
    /// Ray direction (unit length).
    pub direction: Vec3,
    /// Where the ray meets the object.
    pub hit: Vec3,
    /// The scene triangle hit.
    pub triangle: u32,
    /// Sampling phase of the ray (0: uniform, 1: aimed, 2…6: targeted rounds;
    /// [`HUNT_PHASE`](super::HUNT_PHASE): a `--hunt` ray aimed at a culled object).
    pub phase: u32,
    /// Global index of the ray in the cell's budget (`0..rays`).
    pub ray: u64,
}

/// The sampled visible set of one cell.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CellSample {
    /// Visible object ids, ascending: objects some ray sees, plus objects whose bounds
    /// overlap the cell (visible by definition).
    pub visible: Vec<u32>,
    /// Per entry of `visible`: the first ray that saw it; `None` for an object no ray hit
    /// that is visible only because its bounds overlap the cell.
    pub witness: Vec<Option<Witness>>,
    /// Objects first found in the last 10 % of the ray budget (a hint that more rays may find
    /// more).
    pub late_found: u32,
    /// Rays actually cast (less than asked when everything was found early).
    pub rays_cast: u64,
}

impl CellSample {
    /// The witness of object `object` if it is in the visible set (`Some(None)` for an
    /// overlap-only object).
    pub fn witness_of(&self, object: u32) -> Option<Option<&Witness>> {
        self.visible
            .binary_search(&object)
            .ok()
            .map(|i| self.witness[i].as_ref())
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum PhaseKind {
    Uniform,
    Aimed,
    Targeted,
}

#[derive(Clone, Copy, Debug)]
struct Phase {
    kind: PhaseKind,
    start: u64,
    end: u64,
}

/// Ray `k` tenths into a budget of `n` rays.
fn tenth(n: u64, k: u64) -> u64 {
    (u128::from(n) * u128::from(k) / 10) as u64
}

fn plan(n: u64) -> Vec<Phase> {
    let mut p = vec![
        Phase {
            kind: PhaseKind::Uniform,
            start: 0,
            end: tenth(n, 2),
        },
        Phase {
            kind: PhaseKind::Aimed,
            start: tenth(n, 2),
            end: tenth(n, 5),
        },
    ];
    for k in 5..10 {
        p.push(Phase {
            kind: PhaseKind::Targeted,
            start: tenth(n, k),
            end: tenth(n, k + 1),
        });
    }
    p
}

/// SplitMix64 finaliser.
fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The random stream of one chunk.
pub(crate) fn chunk_rng(seed: u64, cell: u64, phase: u64, chunk: u64) -> Pcg64Mcg {
    let mut h = mix64(seed);
    h = mix64(h ^ cell);
    h = mix64(h ^ phase.wrapping_mul(0x5851_f42d_4c95_7f2d));
    h = mix64(h ^ chunk);
    let lo = mix64(h ^ 0x1234_5678);
    Pcg64Mcg::new((u128::from(h) << 64) | u128::from(lo))
}

/// Uniform in the open interval (0, 1).
#[inline]
pub(super) fn unit(rng: &mut Pcg64Mcg) -> f64 {
    ((rng.next_u64() >> 11) as f64 + 0.5) * (1.0 / (1u64 << 53) as f64)
}

/// Moves `p` strictly inside `cell` on every axis where the cell has room for it.
pub(super) fn clamp_inside(p: DVec3, cell: &Aabb) -> Vec3 {
    let mut q = p.as_vec3();
    for k in 0..3 {
        let (lo, hi) = (cell.min[k], cell.max[k]);
        if hi <= lo {
            q[k] = lo;
            continue;
        }
        let (a, b) = (lo.next_up(), hi.next_down());
        if a > b {
            q[k] = lo + (hi - lo) * 0.5;
        } else if q[k] < a {
            q[k] = a;
        } else if q[k] > b {
            q[k] = b;
        }
    }
    q
}

/// A point uniform in `cell`, strictly inside it where it has room.
pub(crate) fn uniform_origin(rng: &mut Pcg64Mcg, cell: &Aabb) -> Vec3 {
    let (lo, size) = (cell.min.as_dvec3(), cell.size().as_dvec3());
    let u = DVec3::new(unit(rng), unit(rng), unit(rng));
    clamp_inside(lo + size * u, cell)
}

/// Origins for targeted rays: half uniform, a quarter on a face, a quarter near a corner.
fn targeted_origin(rng: &mut Pcg64Mcg, cell: &Aabb) -> Vec3 {
    let (lo, hi, size) = (
        cell.min.as_dvec3(),
        cell.max.as_dvec3(),
        cell.size().as_dvec3(),
    );
    let kind = rng.next_u64() & 3;
    let mut p = lo + size * DVec3::new(unit(rng), unit(rng), unit(rng));
    match kind {
        2 => {
            let r = rng.next_u64();
            let axis = (r % 3) as usize;
            let inset = size[axis] * 1e-6;
            p[axis] = if r & 4 != 0 {
                hi[axis] - inset
            } else {
                lo[axis] + inset
            };
        }
        3 => {
            let r = rng.next_u64();
            for axis in 0..3 {
                let d = size[axis] * (1e-6 + 0.02 * unit(rng));
                p[axis] = if r & (1 << axis) != 0 {
                    hi[axis] - d
                } else {
                    lo[axis] + d
                };
            }
        }
        _ => {}
    }
    clamp_inside(p, cell)
}

/// A direction uniform on the unit sphere.
pub(crate) fn sphere_direction(rng: &mut Pcg64Mcg) -> DVec3 {
    let z = 1.0 - 2.0 * unit(rng);
    let phi = std::f64::consts::TAU * unit(rng);
    let r = (1.0 - z * z).max(0.0).sqrt();
    DVec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// A random point of object `o`: uniform in its bounds or on its surface (area-weighted).
fn target_point(rng: &mut Pcg64Mcg, rays: &SceneRays, o: u32) -> DVec3 {
    let (pick, r1, r2) = (unit(rng), unit(rng), unit(rng));
    if rng.next_u64() & 1 == 0 {
        let b = rays.object_bounds(o);
        let (lo, size) = (b.min.as_dvec3(), b.size().as_dvec3());
        lo + size * DVec3::new(pick, r1, r2)
    } else {
        rays.surface_point(o, pick, r1, r2)
            .unwrap_or_else(|| rays.object_bounds(o).center().as_dvec3())
    }
}

/// One ray of the given phase: (origin, unit direction).
fn make_ray(
    kind: PhaseKind,
    rng: &mut Pcg64Mcg,
    cell: &Aabb,
    targets: &[u32],
    rays: &SceneRays,
) -> (Vec3, Vec3) {
    let origin = match kind {
        PhaseKind::Targeted => targeted_origin(rng, cell),
        _ => uniform_origin(rng, cell),
    };
    let mut dir = DVec3::ZERO;
    if kind != PhaseKind::Uniform && !targets.is_empty() {
        let o = targets[(rng.next_u64() % targets.len() as u64) as usize];
        dir = target_point(rng, rays, o) - origin.as_dvec3();
    }
    let len = dir.length();
    let mut d = if len > 1e-12 * (1.0 + origin.as_dvec3().abs().max_element()) && len.is_finite() {
        (dir / len).as_vec3()
    } else {
        Vec3::ZERO
    };
    if d == Vec3::ZERO || !d.is_finite() {
        d = sphere_direction(rng).as_vec3();
    }
    (origin, d)
}

/// What one chunk found: objects new to the chunk (and not found by an earlier phase), with
/// the first ray that saw them.
struct Found {
    object: u32,
    ray: u64,
    origin: Vec3,
    direction: Vec3,
    triangle: u32,
    t: f32,
}

struct Scratch {
    seen: Vec<bool>,
    touched: Vec<u32>,
    hits: Vec<RawHit>,
    rays: Vec<(Vec3, Vec3)>,
}

/// Samples the visible set of `cell` with `rays` rays. `rays_index` is the [`SceneRays`]
/// built from `scene`; `cell_index` selects the cell's random streams (use the cell's position
/// in the PVS); `alpha_blocks` makes see-through triangles block like opaque ones (the PVS
/// setting `alpha_occluders`).
///
/// The budget is cut at tenths (`b(k) = rays·k/10`): rays `[0, b2)` start uniformly in the
/// cell with directions uniform on the sphere; rays `[b2, b5)` are aimed at a random point of
/// a random object (inside its bounds or on its surface, area-weighted); rays `[b5, b10)` are
/// five targeted rounds aimed only at the objects not found by the earlier rounds, half of
/// them starting on the cell's faces or near its corners. When every object with area has
/// been found, the remaining rays are not cast ([`CellSample::rays_cast`]).
///
/// Runs on the current rayon pool; the result does not depend on its size: rays are cut into
/// chunks of [`CHUNK`] with their own random streams, and an object's witness is the ray
/// with the smallest index.
pub fn sample_cell(
    rays_index: &SceneRays,
    scene: &Scene,
    cell: Aabb,
    rays: u64,
    seed: u64,
    cell_index: u64,
    alpha_blocks: bool,
) -> CellSample {
    sample_cell_progress(
        rays_index,
        scene,
        cell,
        rays,
        seed,
        cell_index,
        alpha_blocks,
        None,
    )
}

/// [`sample_cell`], advancing `progress` by the rays cast (and by the rays skipped when the
/// sampling stops early).
#[expect(
    clippy::too_many_arguments,
    reason = "the sampler inputs (scene, cell, ray count, seed, cell index, alpha rule, progress) are independent; callers pass them straight through"
)]
pub(crate) fn sample_cell_progress(
    index: &SceneRays,
    scene: &Scene,
    cell: Aabb,
    rays: u64,
    seed: u64,
    cell_index: u64,
    alpha_blocks: bool,
    progress: Option<&super::check::ProgressFn>,
) -> CellSample {
    const NONE: u32 = u32::MAX;
    let n_obj = scene.objects.len();
    // first[o]: index into `found` of object o's witness.
    let mut first: Vec<u32> = vec![NONE; n_obj];
    let mut found: Vec<(u32, Witness)> = Vec::new();
    let late_from = tenth(rays, 9);
    let mut rays_cast = 0u64;

    for (p, phase) in plan(rays).into_iter().enumerate() {
        let count = phase.end - phase.start;
        if count == 0 {
            continue;
        }
        let targets: Vec<u32> = match phase.kind {
            PhaseKind::Uniform => Vec::new(),
            PhaseKind::Aimed => index.targetable_objects().to_vec(),
            PhaseKind::Targeted => index
                .targetable_objects()
                .iter()
                .copied()
                .filter(|&o| first[o as usize] == NONE)
                .collect(),
        };
        if phase.kind == PhaseKind::Targeted && targets.is_empty() {
            break;
        }
        let chunks = count.div_ceil(CHUNK);
        let known = &first;
        let targets = &targets;
        let results: Vec<Vec<Found>> = (0..chunks)
            .into_par_iter()
            .map_init(
                || Scratch {
                    seen: vec![false; n_obj],
                    touched: Vec::new(),
                    hits: Vec::new(),
                    rays: Vec::new(),
                },
                |s, c| {
                    let mut rng = chunk_rng(seed, cell_index, p as u64, c);
                    let begin = phase.start + c * CHUNK;
                    let end = (begin + CHUNK).min(phase.end);
                    let mut out = Vec::new();
                    // Make all rays first: their random memory accesses (points on objects)
                    // then overlap instead of stalling one ray at a time.
                    s.rays.clear();
                    s.rays.extend(
                        (begin..end).map(|_| make_ray(phase.kind, &mut rng, &cell, targets, index)),
                    );
                    for (ray, &(o, d)) in (begin..end).zip(&s.rays) {
                        index.trace_raw(o, d, alpha_blocks, &mut s.hits);
                        for h in &s.hits {
                            let m = index.meta(h.slot);
                            let obj = m.object as usize;
                            if s.seen[obj] || known[obj] != NONE {
                                continue;
                            }
                            s.seen[obj] = true;
                            s.touched.push(m.object);
                            out.push(Found {
                                object: m.object,
                                ray,
                                origin: o,
                                direction: d,
                                triangle: m.triangle,
                                t: h.t,
                            });
                        }
                    }
                    for &o in &s.touched {
                        s.seen[o as usize] = false;
                    }
                    s.touched.clear();
                    if let Some(pb) = progress {
                        pb(super::check::Progress::Advance(end - begin));
                    }
                    // Within one ray, several objects may be new: keep ray order, then
                    // object order, so the list does not depend on traversal order.
                    out.sort_by_key(|f| (f.ray, f.object));
                    out
                },
            )
            .collect();
        for f in results.into_iter().flatten() {
            let slot = &mut first[f.object as usize];
            if *slot == NONE {
                *slot = found.len() as u32;
                found.push((
                    f.object,
                    Witness {
                        origin: f.origin,
                        direction: f.direction,
                        hit: SceneRays::precise_hit(scene, f.triangle, f.origin, f.direction, f.t),
                        triangle: f.triangle,
                        phase: p as u32,
                        ray: f.ray,
                    },
                ));
            }
        }
        rays_cast += count;
    }
    if let Some(pb) = progress {
        pb(super::check::Progress::Advance(rays - rays_cast));
    }

    let late_found = found.iter().filter(|(_, w)| w.ray >= late_from).count() as u32;
    let mut entries: Vec<(u32, Option<Witness>)> =
        found.into_iter().map(|(o, w)| (o, Some(w))).collect();
    for (o, obj) in scene.objects.iter().enumerate() {
        if first[o] == NONE && obj.bounds.overlaps(&cell) {
            entries.push((o as u32, None));
        }
    }
    entries.sort_by_key(|e| e.0);
    let (visible, witness) = entries.into_iter().unzip();
    CellSample {
        visible,
        witness,
        late_found,
        rays_cast,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::vec3;
    use std::path::Path;

    #[test]
    fn plan_covers_the_budget_and_the_last_round_is_the_last_tenth() {
        for n in [1u64, 7, 10, 999, 1_000_000, u64::MAX / 3] {
            let p = plan(n);
            assert_eq!(p[0].start, 0);
            for w in p.windows(2) {
                assert_eq!(w[0].end, w[1].start);
            }
            assert_eq!(p.last().unwrap().end, n);
            assert_eq!(p.last().unwrap().start, tenth(n, 9));
        }
    }

    #[test]
    fn origins_are_strictly_inside_the_cell() {
        let cell = Aabb::new(vec3(1.0, 2.0, 3.0), vec3(1.5, 2.001, 40.0));
        let mut rng = chunk_rng(1, 2, 3, 4);
        for _ in 0..20_000 {
            for p in [
                uniform_origin(&mut rng, &cell),
                targeted_origin(&mut rng, &cell),
            ] {
                assert!(p.cmpgt(cell.min).all() && p.cmplt(cell.max).all(), "{p:?}");
            }
        }
    }

    #[test]
    fn streams_differ_per_chunk_and_repeat_per_key() {
        let a = chunk_rng(7, 0, 1, 2).next_u64();
        assert_eq!(a, chunk_rng(7, 0, 1, 2).next_u64());
        assert_ne!(a, chunk_rng(7, 0, 1, 3).next_u64());
        assert_ne!(a, chunk_rng(7, 1, 1, 2).next_u64());
        assert_ne!(a, chunk_rng(8, 0, 1, 2).next_u64());
    }

    #[test]
    fn overlapping_object_is_visible_by_definition() {
        // A zero-area triangle inside the cell: no ray can hit it, its bounds overlap the cell.
        let tiny = vec![[
            vec3(0.0, 0.0, 0.0),
            vec3(0.5, 0.0, 0.0),
            vec3(0.25, 0.0, 0.0),
        ]];
        let scene = Scene::from_objects(Path::new("mem"), vec![("tiny".into(), tiny, true)]);
        let index = SceneRays::new(&scene);
        let cell = Aabb::new(Vec3::splat(-1.0), Vec3::splat(1.0));
        let s = sample_cell(&index, &scene, cell, 10, 1, 0, false);
        assert_eq!(s.visible, vec![0]);
        assert_eq!(s.witness, vec![None]);
    }
}
