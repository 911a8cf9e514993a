//! The shrunk-occluder sampling culler (fine foliage; Wonka, Wimmer, Schmalstieg 2000,
//! generalised to thin leaves as `../shared/notes/shrunk-occluder-sampling.md` describes):
//! sample points on the cell's faces, each standing for a ball of radius ε, render the outward
//! hemisphere with every occluder shrunk for that ball (`crate::sampler`), and an object hidden
//! from every ball of every face is hidden from the cell.
//!
//! # Why it is conservative
//!
//! 1. **The boundary suffices.** An object whose box meets the closed cell is never tested
//!    (it stays visible). Otherwise, if a point `p0` of the cell sees a point `q` of the object,
//!    the segment `p0 q` leaves the cell at a point `b` of some face `F`, with `q` on the outer
//!    side of `F`'s plane (closed half-space), and `b` sees `q` along the rest of the segment.
//! 2. **Balls cover each face.** A face is cut into rectangles (a grid, then quadrants); each
//!    rectangle is sampled at its centre with ε = its half diagonal (rounded up), so the ball
//!    holds the rectangle. Children split a rectangle exactly at its midpoints, so the
//!    rectangles of any refinement still cover the face.
//! 3. **One render per rectangle** (`crate::sampler`, whose docs carry the proof, for balls and
//!    for rectangles of the face's plane): an object whose every box direction in the outer
//!    hemisphere of `F` is covered by a shrunk occluder nearer than the box is hidden from
//!    every point of the rectangle looking out through `F`. The reported ε of a rectangle is
//!    its half diagonal (the ball holding it); each edge is shrunk for the rectangle's extent
//!    across it, at most that. Its pieces may be tested instead of its box (their
//!    union holds all its triangles), and a piece's triangles instead of the piece.
//!    A rectangle may take several renders, one per band of the objects' farthest distance
//!    from its centre (`sampling_band_ratio`), each testing only its band's objects with edges
//!    shrunk for them (depth-bounded shrinks). With several bands, a first render for all the
//!    rectangle's objects, shrunk for the farthest of them, comes before (`sampling_whole_first`):
//!    a render's shrinks hold for every occludee no farther than its farthest box, so what it
//!    hides is hidden, and the bands then render only for the objects it leaves open. Every
//!    object is decided by one render that holds for it: hidden in one of them, or open in the
//!    last that tests it.
//! 4. **Refinement only decides more.** An object still undecided at a ball is re-tested in
//!    the ball's four children; an object undecided at the finest ε, or when the budget runs
//!    out, stays visible. An object is culled only when every leaf rectangle of every face
//!    proved it hidden. Levels are sampled breadth-first (every rectangle of a level before
//!    any of the next), so a budget that runs out costs the finest levels, not whole faces;
//!    the order never changes which rectangles cover a face, only how many are sampled.
//!    Levels coarser than `--sampling-max-eps` are split without being sampled: their
//!    quadrants cover them exactly and inherit every candidate. So is the rest of a level
//!    (never the finest) whose probe, every 16th of its rectangles (8 to about 64 of them,
//!    [`probe_stride`]), proves hidden less than
//!    `--sampling-probe` of the objects it tests, or hides at every probed rectangle that
//!    tests them less than `--sampling-probe-cull` of the undecided objects it tests (and at
//!    least one), or, for the level just above the finest, is expected to save the finest
//!    level less than it costs (`--sampling-probe-pay`: a pilot renders a few probed
//!    rectangles and their quadrants with and without what the probe proved, in polygons
//!    drawn, [`Shared::pilot`]): a heuristic —
//!    the level's balls then do not fuse the occluders, so its points cost more than they
//!    save the finer levels; only which rectangles are sampled depends on it, never
//!    soundness (the pilot's trial renders decide nothing). The probed
//!    rectangles pass on what they left open, the others every candidate still undecided.
//! 5. **Certification only keeps objects.** Objects seen by a real ray (the validator's
//!    sampler from the cell, or a ray from a sample point) are visible for sure and leave the
//!    candidate list; that can only keep objects in the PVS.
//!
//! **The same on any thread count.** A level's rectangles run in lanes of consecutive ones
//! (lengths fixed by their number, [`lanes`]), each lane in order and 16 lanes at a time in
//! parallel; each rectangle decides with what was known visible when its 16 lanes began and
//! what its own lane found since, never with what another lane finds meanwhile (that changed
//! its candidate list, hence its distance bands and shrinks). So the PVS, the points and the
//! cost curve do not depend on the threads, unless the point or time budget runs out
//! mid-level.
//!
//! **Checkpoints** (`super::checkpoint`, `bake --resume`). Chunk boundaries are where a cell's
//! progress is saved: a resumed cell replays the recorded chunks (their rectangles' outcomes
//! and counts, the probe decisions and cost-curve entries made) and starts the next chunk from
//! the known-visible set saved at the cut, which is what the interrupted run started it from.
//! So it hides exactly what an uninterrupted run hides: nothing is decided that the same code
//! did not decide from the same state.
//!
//! Occluders are every exactly planar convex polygon of the scene's occluder objects, including
//! objects earlier cullers hid (they are real geometry: blocking rays with them is sound).

use super::BakeError;
use super::checkpoint::{CellCheckpoint, RectRecord};
use super::pipeline::{CullState, Culler, CullerWork, PlaneSink};
use super::prepare::Prepared;
use crate::backend::gpu::GpuBackend;
use crate::backend::gpu::sampler::{GpuSampler, GpuSamplerScene};
use crate::backend::{BackendError, RasterBackend};
use crate::geom::{Aabb, DAabb};
use crate::pvs::SamplingLevel;
use crate::sampler::{BoxTest, Hemicube, Occludees, RectSweep, SampleOccluders};
use crate::scene::Scene;
use crate::settings::{SamplingFusion, SamplingSettings};
use crate::validate::SceneRays;
use glam::DVec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// The per-scene data of the sampler, built once by [`super::Prepared`].
pub struct SamplerData {
    /// The occluder polygons and their BVH.
    pub occluders: SampleOccluders,
    /// The ray caster used to certify visible objects.
    pub rays: SceneRays,
    /// The finest ε in use (given, or chosen from the occluders).
    pub eps: f64,
    /// Where `eps` came from, one line for the summary.
    pub eps_reason: String,
    /// The sampler's settings.
    pub settings: SamplingSettings,
}

impl std::fmt::Debug for SamplerData {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SamplerData")
            .field("occluders", &self.occluders)
            .field("eps", &self.eps)
            .finish()
    }
}

impl SamplerData {
    /// Builds the sampler's occluders and ray caster for a prepared scene.
    pub fn new(
        prepared_occ: &crate::project::occluders::Occluders,
        scene: &crate::scene::Scene,
        settings: &super::BakeSettings,
    ) -> Self {
        // The sampler casts few rays (`--sampling-rays` per cell and a few per sample point),
        // so its ray caster takes a fast build: on the paper-size forest 8 s instead of 32 s,
        // for about 0.06 s more per cell at 100,000 rays (`SceneRays::with_build`). (Built
        // beside the polygons' BVH, the two took 1.5 GB more at once for 7 s less.)
        let occluders = SampleOccluders::new(scene, prepared_occ, settings.alpha_occluders);
        let rays = SceneRays::with_build(scene, obvhs::BvhBuildParams::fast_build());
        let s = settings.sampling_settings;
        let (eps, eps_reason) = match s.eps {
            Some(e) => (e, format!("--sampling-eps {e}")),
            None if occluders.median_inradius > 0.0 => {
                let e = SamplingSettings::EPS_PER_INRADIUS * occluders.median_inradius;
                (
                    e,
                    format!(
                        "{} × the occluders' median inradius {:.4}",
                        SamplingSettings::EPS_PER_INRADIUS,
                        occluders.median_inradius
                    ),
                )
            }
            None => (1.0, "no occluder polygons".into()),
        };
        SamplerData {
            occluders,
            rays,
            eps,
            eps_reason,
            settings: s,
        }
    }
}

/// The culler: see the module docs.
#[derive(Debug, Default)]
pub struct SamplingCuller {
    /// With the GPU backend: the occluder polygons on its device, uploaded by the first cell
    /// and kept for the bake.
    gpu_scene: Mutex<Option<Arc<GpuSamplerScene>>>,
    /// The GPU samplers' device memory over all levels of all cells
    /// ([`GpuBackend::sampler_memory`]).
    gpu_use: DeviceUse,
}

/// The device memory a bake's GPU samplers take: now, at most, the budget, and how long lanes
/// waited for a sampler because the budget held no more.
#[derive(Debug, Default)]
struct DeviceUse {
    /// Bytes of the samplers alive.
    live: AtomicU64,
    /// Most bytes alive at once.
    peak: AtomicU64,
    /// The budget ([`GpuBackend::sampler_memory`]; 0 before a GPU level).
    budget: AtomicU64,
    /// Nanoseconds lanes waited for a sampler, summed over the lanes.
    waited_ns: AtomicU64,
}

impl DeviceUse {
    /// Adds `bytes` to the live ones when they stay within `budget` (any `None`), raising the
    /// peak; false, adding nothing, when they would not.
    fn add(&self, bytes: u64, budget: Option<u64>) -> bool {
        let added = self
            .live
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |l| {
                let now = l.saturating_add(bytes);
                budget.is_none_or(|b| now <= b).then_some(now)
            });
        if let Ok(before) = added {
            self.peak.fetch_max(before + bytes, Ordering::AcqRel);
        }
        added.is_ok()
    }
}

/// Device memory the GPU samplers of a bake may take together by default
/// ([`GpuBackend::sampler_memory`]; each is its maps, 8× the resolution squared per view, and
/// per-render buffers: about 0.7 GB at 512 pixels for the fine forest, 1.8 GB at 1,024). A
/// level makes its first sampler whatever the budget, and more only while the bake's samplers
/// fit; beyond, its lanes wait for one of its own (a GPU gains little from more renders in
/// flight than it takes to keep it busy).
pub const GPU_SAMPLERS_BUDGET: u64 = crate::backend::gpu::sampler::DEFAULT_SAMPLER_MEMORY;

/// The renderers of one level, shared by its lanes: a lane takes a free one, or makes one
/// (the level's first always; more while `live + bytes ≤ budget`, `live` counting every
/// level's), or waits until another lane of the level gives one back. A lane holds a renderer
/// only while it renders its rectangles, which never waits on anything, so a wait ends.
/// Dropping the pool drops its renderers and gives their bytes back to `live`.
struct Pool<'l, T> {
    state: Mutex<(Vec<T>, usize)>,
    given: std::sync::Condvar,
    bytes: u64,
    budget: u64,
    used: &'l DeviceUse,
}

impl<'l, T> Pool<'l, T> {
    /// A pool whose renderers take `bytes` each of a `budget` shared through `used`.
    fn new(bytes: u64, budget: u64, used: &'l DeviceUse) -> Self {
        Pool {
            state: Mutex::new((Vec::new(), 0)),
            given: std::sync::Condvar::new(),
            bytes,
            budget,
            used,
        }
    }

    /// Renderers made (and not failed) so far.
    #[cfg(test)]
    fn made(&self) -> usize {
        self.state.lock().unwrap_or_else(|e| e.into_inner()).1
    }

    /// Reserves one renderer's bytes when they fit the budget.
    fn reserve(&self) -> bool {
        self.used.add(self.bytes, Some(self.budget))
    }

    /// A renderer: a free one, a new one from `make` (`None` when it fails), or the next one
    /// given back.
    fn take(&self, make: impl FnOnce() -> Option<T>) -> Option<T> {
        let mut st = self.state.lock().unwrap_or_else(|e| e.into_inner());
        loop {
            if let Some(r) = st.0.pop() {
                return Some(r);
            }
            let first = st.1 == 0;
            if first || self.reserve() {
                if first {
                    self.used.add(self.bytes, None);
                }
                st.1 += 1;
                drop(st);
                let r = make();
                if r.is_none() {
                    let mut st = self.state.lock().unwrap_or_else(|e| e.into_inner());
                    st.1 -= 1;
                    self.used.live.fetch_sub(self.bytes, Ordering::AcqRel);
                    self.given.notify_all();
                }
                return r;
            }
            let t = Instant::now();
            st = self.given.wait(st).unwrap_or_else(|e| e.into_inner());
            self.used
                .waited_ns
                .fetch_add(t.elapsed().as_nanos() as u64, Ordering::Relaxed);
        }
    }

    /// Gives a renderer back for the level's other lanes.
    fn give(&self, r: T) {
        let mut st = self.state.lock().unwrap_or_else(|e| e.into_inner());
        st.0.push(r);
        self.given.notify_one();
    }

    /// Drops the renderers not in use, so that their memory is free for other work (a
    /// level's pilot); [`Pool::take`] makes new ones when asked.
    fn clear(&self) {
        let free = {
            let mut st = self.state.lock().unwrap_or_else(|e| e.into_inner());
            let free = std::mem::take(&mut st.0);
            st.1 -= free.len();
            self.used
                .live
                .fetch_sub(free.len() as u64 * self.bytes, Ordering::AcqRel);
            free
        };
        drop(free);
    }
}

impl<T> Drop for Pool<'_, T> {
    fn drop(&mut self) {
        let made = self.state.get_mut().map_or(0, |st| st.1) as u64;
        self.used
            .live
            .fetch_sub(made * self.bytes, Ordering::AcqRel);
    }
}

impl SamplingCuller {
    /// The culler's name ([`Culler::name`]; in [`crate::bake::CULLER_NAMES`]).
    pub const NAME: &'static str = super::SHRUNK_SAMPLING;

    /// The occluder polygons on `gpu`'s device, and the occludees' triangles where they fit
    /// (uploaded once per bake: a triangle test then sends indices, not corners).
    fn gpu_scene(
        &self,
        gpu: &GpuBackend,
        occ: &SampleOccluders,
        scene: &Scene,
    ) -> Result<Arc<GpuSamplerScene>, BakeError> {
        let mut slot = self.gpu_scene.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(s) = slot.as_ref() {
            return Ok(s.clone());
        }
        let mut s = GpuSamplerScene::new(gpu, occ)?;
        // Out of device memory for them: each test uploads its triangles instead.
        if let Err(e) =
            s.upload_triangles(gpu, (0..scene.triangles.len()).map(|t| scene.triangle(t)))
            && !falls_back(&e)
        {
            return Err(e.into());
        }
        let s = Arc::new(s);
        *slot = Some(s.clone());
        Ok(s)
    }
}

/// What renders a rectangle: the CPU's hemicube, or its GPU twin (with the GPU backend on a
/// device with `SHADER_F64`), which gives the same answers (module docs of
/// `backend::gpu::sampler`; it leaves out cards and polygons of more than eight vertices, so
/// with those it can hide less). A level whose GPU sampler the device cannot make renders
/// on the CPU's ([`falls_back`]).
enum Renderer<'a> {
    Cpu(Box<Hemicube>),
    Gpu(Box<GpuSampler<'a>>),
    /// The per-rectangle occlusion sweep (`--sampling-fusion sweep`; CPU only).
    Sweep(Box<RectSweep>),
}

impl Renderer<'_> {
    /// The CPU's renderer at `res` pixels per view for settings `s`: the sweep, or the
    /// hemicube with the tuck pass when `s.tuck`.
    fn cpu(res: u32, s: &SamplingSettings) -> Self {
        if s.fusion == SamplingFusion::Sweep {
            return Renderer::Sweep(Box::new(RectSweep::new(res)));
        }
        let mut hc = Hemicube::new(res);
        hc.set_tuck(s.tuck);
        Renderer::Cpu(Box::new(hc))
    }
}

/// Whether a failure to make a GPU sampler leaves the device usable, so that the CPU's
/// hemicube can render in its place: the sampler does not fit (its textures or buffers exceed
/// the device's limits) or its memory could not be had. A lost or failing device ends the
/// bake instead.
fn falls_back(e: &BackendError) -> bool {
    !e.device_failed() || matches!(e, BackendError::OutOfMemory { .. })
}

/// Certifying rays per undecided object and sample point at most.
const CERTIFY_PER_OBJECT: usize = 2;
/// Certifying rays per sample point at most.
const CERTIFY_PER_POINT: usize = 64;

/// A sampled rectangle's outcome: the objects it leaves undecided for its quadrants (none:
/// nothing to refine) and what it counted, for the checkpoint.
type Outcome = (Option<Arc<Vec<u32>>>, RectRecord);

/// A rectangle's candidates as the per-rectangle sweep tests them ([`Occludees`]): their
/// boxes, and the prepared pieces and triangles of the scene.
struct SweepObjects<'a> {
    prepared: &'a Prepared<'a>,
    list: &'a [u32],
    boxes: &'a [DAabb],
}

impl Occludees for SweepObjects<'_> {
    fn len(&self) -> usize {
        self.list.len()
    }
    fn object_box(&self, i: usize) -> DAabb {
        self.boxes[i]
    }
    fn pieces(&self, i: usize) -> std::ops::Range<u32> {
        self.prepared.pieces[self.list[i] as usize].clone()
    }
    fn piece_box(&self, k: u32) -> DAabb {
        self.prepared.piece_boxes[k as usize]
    }
    fn piece_triangles(&self, k: u32) -> &[u32] {
        let r = &self.prepared.piece_triangle_ranges[k as usize];
        &self.prepared.piece_triangles[r.start as usize..r.end as usize]
    }
    fn triangle(&self, t: u32) -> [DVec3; 3] {
        self.prepared
            .scene
            .triangle(t as usize)
            .map(|v| v.as_dvec3())
    }
}

/// One rectangle of a face: `[b0, b1] × [c0, c1]` on the face's plane.
#[derive(Clone, Copy, Debug)]
struct Patch {
    face: usize,
    b: [f64; 2],
    c: [f64; 2],
}

impl Patch {
    /// Half its diagonal: the radius of the ball around its centre that holds it.
    fn half_diagonal(&self) -> f64 {
        0.5 * (self.b[1] - self.b[0]).hypot(self.c[1] - self.c[0])
    }

    /// Its half sides along the face's two axes.
    fn half_sides(&self) -> (f64, f64) {
        (0.5 * (self.b[1] - self.b[0]), 0.5 * (self.c[1] - self.c[0]))
    }

    /// The ε its sample point is rendered with: its half diagonal, rounded up.
    fn ball_eps(&self) -> f64 {
        let (hb, hc) = self.half_sides();
        (hb * hb + hc * hc).sqrt() * (1.0 + 1e-9)
    }

    /// The four rectangles that split this one at its midpoints (they cover it exactly).
    fn quadrants(&self) -> impl Iterator<Item = Patch> + use<> {
        let (p, bm, cm) = (
            *self,
            0.5 * (self.b[0] + self.b[1]),
            0.5 * (self.c[0] + self.c[1]),
        );
        [
            ([p.b[0], bm], [p.c[0], cm]),
            ([bm, p.b[1]], [p.c[0], cm]),
            ([p.b[0], bm], [cm, p.c[1]]),
            ([bm, p.b[1]], [cm, p.c[1]]),
        ]
        .into_iter()
        .map(move |(b, c)| Patch { face: p.face, b, c })
    }
}

/// One face of the cell: outward normal `sign × e_axis`, its plane coordinate.
#[derive(Clone, Copy, Debug)]
struct Face {
    axis: usize,
    sign: f64,
    plane: f64,
}

/// What one cell's sampling shares between threads.
struct Shared<'a> {
    data: &'a SamplerData,
    prepared: &'a Prepared<'a>,
    faces: [Face; 6],
    /// Per object: known visible (certified, given up, or out of budget).
    done: Vec<AtomicBool>,
    points: AtomicU64,
    polygons: AtomicU64,
    /// The cell's finest ε (the settings', or `1/√2` of it where pixels are traded for
    /// points: [`SamplingSettings::cell_finest`]).
    finest_eps: f64,
    /// The smallest ε rendered, as f64 bits (positive floats order like their bits).
    finest: AtomicU64,
    /// Object tests at a sample point so far, and those that proved the object hidden there
    /// (a level's probe compares them).
    tested: AtomicU64,
    hid: AtomicU64,
    start: Instant,
    /// The first device failure (the rectangles it hit gave their objects up as visible).
    failed: Mutex<Option<BackendError>>,
    /// Why some GPU sampler could not be made and the CPU's hemicube rendered instead (the
    /// first reason; [`CullerWork::cpu_fallback`]).
    fallback: Mutex<Option<String>>,
}

impl Culler for SamplingCuller {
    fn name(&self) -> &'static str {
        Self::NAME
    }

    /// With GPU samplers: the most device memory they took at once against the budget, and
    /// how long lanes waited for one (`--gpu-sampler-memory` lets more run at once).
    fn note(&self) -> Option<String> {
        let u = &self.gpu_use;
        let budget = u.budget.load(Ordering::Relaxed);
        if budget == 0 {
            return None;
        }
        let gb = |b: u64| b as f64 / f64::from(1u32 << 30);
        let waited = u.waited_ns.load(Ordering::Relaxed) as f64 * 1e-9;
        Some(format!(
            "GPU samplers took at most {:.2} GiB at once of the {:.2} GiB allowed{}",
            gb(u.peak.load(Ordering::Relaxed)),
            gb(budget),
            if waited > 0.0 {
                format!(
                    "; threads waited {waited:.1} s in all for one (--gpu-sampler-memory allows more)"
                )
            } else {
                String::new()
            }
        ))
    }

    fn cull(
        &self,
        prepared: &Prepared,
        cell: &Aabb,
        backend: &dyn RasterBackend,
        state: &mut CullState,
        _observe: &mut dyn PlaneSink,
    ) -> Result<CullerWork, BakeError> {
        let Some(data) = prepared.sampler.as_ref() else {
            return Ok(CullerWork::default());
        };
        let scene = prepared.scene;
        let n = scene.objects.len();
        let cb = cell.to_f64();
        let known = state.known_visible;
        let mut candidates: Vec<u32> = (0..n as u32)
            .filter(|&o| {
                let ob = &scene.objects[o as usize];
                !state.hidden[o as usize]
                    && !known.is_some_and(|k| k[o as usize])
                    && !ob.bounds.is_empty()
                    && !ob.bounds.to_f64().overlaps(&cb)
            })
            .collect();
        if candidates.is_empty() {
            return Ok(CullerWork::default());
        }
        let done: Vec<AtomicBool> = (0..n).map(|_| AtomicBool::new(false)).collect();
        if data.settings.rays > 0 {
            let seed = cell_seed(cell);
            let sample = crate::validate::sample_cell(
                &data.rays,
                scene,
                *cell,
                data.settings.rays,
                seed,
                0,
                prepared.settings.alpha_occluders,
            );
            for &o in &sample.visible {
                done[o as usize].store(true, Ordering::Relaxed);
            }
            candidates.retain(|&o| !done[o as usize].load(Ordering::Relaxed));
        }
        // The automatic resolution's scale: where the cell's rays first hit (NaN: never).
        let hit_distance = if data.settings.resolution.is_none() {
            median_hit_distance(
                &data.rays,
                cell,
                cell_seed(cell),
                prepared.settings.alpha_occluders,
            )
        } else {
            f64::NAN
        };
        // The cell's finest ε and its cap on the automatic resolution (pixels traded for
        // points); the finest ε fixes the cell's rectangles, so a checkpoint must match it.
        let (finest_eps, resolution_cap) = data.settings.cell_finest(data.eps, hit_distance);
        // A checkpoint of this cell (`--resume`): what was known visible at its cut; its
        // rectangles are replayed below.
        let (ckpt, resumed) = match prepared.checkpoints {
            Some(spec) => {
                let (c, r) = CellCheckpoint::open(spec, cell, cell_seed(cell), n, finest_eps);
                (Some(c), r)
            }
            None => (None, None),
        };
        if let Some(r) = &resumed {
            for (d, &k) in done.iter().zip(&r.known) {
                if k {
                    d.store(true, Ordering::Relaxed);
                }
            }
        }
        let ckpt_failed: Mutex<Option<BakeError>> = Mutex::new(None);
        // A checkpoint failed (or a test interrupted the bake): the cell fails below.
        let stopped = || {
            ckpt_failed
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .is_some()
        };
        // Faces in the order −x, +x, −y, +y, −z, +z.
        let faces: [Face; 6] = std::array::from_fn(|k| {
            let (axis, sign) = (k / 2, if k % 2 == 0 { -1.0 } else { 1.0 });
            Face {
                axis,
                sign,
                plane: if sign > 0.0 {
                    cb.max[axis]
                } else {
                    cb.min[axis]
                },
            }
        });
        let s = data.settings;
        // The GPU twin of the hemicube, with the GPU backend where the device has `f64` and
        // room for the polygons (otherwise the CPU's, which the summary reports).
        // Settings without a GPU twin (the tuck pass) keep the sampler on the CPU.
        let gpu_scene = match backend.as_gpu() {
            Some(_) if s.gpu_refusal().is_some() => None,
            Some(g) if GpuSamplerScene::refusal(g, &data.occluders).is_none() => {
                Some((g, self.gpu_scene(g, &data.occluders, prepared.scene)?))
            }
            _ => None,
        };
        let eps0 = top_eps(&cb, finest_eps, s.levels, s.budget_points);
        let shared = Shared {
            data,
            prepared,
            faces,
            done,
            points: AtomicU64::new(0),
            polygons: AtomicU64::new(0),
            finest_eps,
            finest: AtomicU64::new(f64::INFINITY.to_bits()),
            tested: AtomicU64::new(0),
            hid: AtomicU64::new(0),
            start: resumed
                .as_ref()
                .and_then(|r| {
                    Instant::now().checked_sub(std::time::Duration::from_secs_f64(r.seconds))
                })
                .unwrap_or_else(Instant::now),
            failed: Mutex::new(None),
            fallback: Mutex::new(
                backend
                    .as_gpu()
                    .and(s.gpu_refusal())
                    .map(|why| format!("{why}; without it the sampler renders on the device")),
            ),
        };
        // Top-level patches: a grid per face whose rectangles' half diagonals are at most eps0.
        let mut top: Vec<(Patch, Arc<Vec<u32>>)> = Vec::new();
        for (k, f) in faces.iter().enumerate() {
            let (b, c) = ((f.axis + 1) % 3, (f.axis + 2) % 3);
            let list: Vec<u32> = candidates
                .iter()
                .copied()
                .filter(|&o| {
                    let ob = scene.objects[o as usize].bounds.to_f64();
                    if f.sign > 0.0 {
                        ob.max[f.axis] >= f.plane
                    } else {
                        ob.min[f.axis] <= f.plane
                    }
                })
                .collect();
            if list.is_empty() {
                continue;
            }
            let list = Arc::new(list);
            let (wb, wc) = (cb.max[b] - cb.min[b], cb.max[c] - cb.min[c]);
            let (nb, nc) = face_grid(wb, wc, eps0);
            let at = |lo: f64, w: f64, i: usize, m: usize| {
                if i == m {
                    lo + w
                } else {
                    lo + w * i as f64 / m as f64
                }
            };
            for i in 0..nb {
                for j in 0..nc {
                    top.push((
                        Patch {
                            face: k,
                            b: [at(cb.min[b], wb, i, nb), at(cb.min[b], wb, i + 1, nb)],
                            c: [at(cb.min[c], wc, j, nc), at(cb.min[c], wc, j + 1, nc)],
                        },
                        list.clone(),
                    ));
                }
            }
        }
        // The pixels per view of a level whose balls have radius `eps`.
        let level_resolution = |eps: f64| {
            s.resolution.unwrap_or_else(|| {
                if s.fusion == SamplingFusion::Sweep {
                    return SamplingSettings::SWEEP_RESOLUTION;
                }
                let r = SamplingSettings::auto_resolution(hit_distance, eps);
                resolution_cap.map_or(r, |c| r.min(c))
            })
        };
        // Breadth-first: every rectangle of one level (in parallel) before any of the next, so
        // that a budget that runs out leaves only the finest levels unsampled, never a face.
        let mut level = top;
        let mut curve: Vec<SamplingLevel> = Vec::new();
        let mut undecided = vec![false; n];
        let mut level_no = 0usize;
        while !level.is_empty() {
            let this_level = level_no;
            level_no += 1;
            let level_eps = level
                .iter()
                .map(|(p, _)| p.half_diagonal())
                .fold(0.0, f64::max);
            if s.max_eps.is_some_and(|m| level_eps > m) && level_eps > finest_eps * (1.0 + 1e-6) {
                // Coarser than `--sampling-max-eps`: split without sampling (the quadrants
                // cover each rectangle exactly, so the faces stay covered) — unless the split
                // holds more rectangles than the budget has points left: then no level below
                // can be sampled whole, and what it would test stays visible (a tiny ε below
                // a larger maximum would otherwise lay out its whole finest level at once).
                let left = shared.points_left();
                if (level.len() as u64).saturating_mul(4) > left {
                    for (_, l) in &level {
                        shared.mark_visible(l);
                    }
                    break;
                }
                level = level
                    .into_iter()
                    .flat_map(|(patch, list)| patch.quadrants().map(move |q| (q, list.clone())))
                    .collect();
                continue;
            }
            let resolution = level_resolution(level_eps);
            let rects_done = |k: usize| {
                if let Some(p) = prepared.sampler_progress {
                    p.rects_done.fetch_add(k as u64, Ordering::Relaxed);
                }
            };
            if let Some(p) = prepared.sampler_progress {
                p.rects_begun
                    .fetch_add(level.len() as u64, Ordering::Relaxed);
            }
            // Rectangles run in lanes of consecutive ones, each lane in order, the lanes of a
            // chunk in parallel. A rectangle decides with what was known visible when its
            // chunk began and what its lane found since, never with what another lane finds
            // meanwhile, so the results do not depend on the threads.
            // Hemicubes are large (about 100 bytes per pixel): lanes take one from the pool
            // and give it back, so a level allocates one per thread, not one per lane, and
            // GPU samplers only as many as the backend's sampler memory holds.
            let pool: Pool<Renderer> = match &gpu_scene {
                None => Pool::new(0, u64::MAX, &self.gpu_use),
                Some((g, scene)) => {
                    self.gpu_use
                        .budget
                        .store(g.sampler_memory(), Ordering::Relaxed);
                    Pool::new(
                        GpuSampler::device_bytes(scene, resolution),
                        g.sampler_memory(),
                        &self.gpu_use,
                    )
                }
            };
            // A GPU sampler the device cannot make at this level's resolution (textures
            // larger than it takes, or out of memory) is replaced by the CPU's hemicube, which
            // gives the same answers, and so is every later one of the level.
            let level_on_cpu = AtomicBool::new(false);
            let new_renderer = || -> Option<Renderer> {
                let cpu = || Some(Renderer::cpu(resolution, &s));
                match &gpu_scene {
                    Some((g, scene)) if !level_on_cpu.load(Ordering::Relaxed) => {
                        match GpuSampler::new(g, scene, resolution) {
                            Ok(gs) => Some(Renderer::Gpu(Box::new(gs))),
                            Err(e) if falls_back(&e) => {
                                level_on_cpu.store(true, Ordering::Relaxed);
                                shared.fall_back(resolution, &e);
                                cpu()
                            }
                            Err(e) => {
                                shared.fail(e);
                                None
                            }
                        }
                    }
                    _ => cpu(),
                }
            };
            let sample = |indices: &[usize]| -> Vec<Option<Arc<Vec<u32>>>> {
                let mut out = Vec::with_capacity(indices.len());
                let (chunk_len, lane_len) = lanes(indices.len());
                for chunk in indices.chunks(chunk_len) {
                    if stopped() {
                        // Stopped (a checkpoint failed, or a test's interruption): the cell
                        // fails below, whatever these rectangles would have found.
                        out.extend(chunk.iter().map(|_| None));
                        rects_done(chunk.len());
                        continue;
                    }
                    // A chunk the checkpoint recorded is replayed, not rendered.
                    if let Some(recs) = ckpt.as_ref().and_then(|c| c.replay(this_level, chunk)) {
                        for (&i, r) in chunk.iter().zip(recs) {
                            shared.replay(level[i].0, &r);
                            out.push(r.open.map(Arc::new));
                        }
                        rects_done(chunk.len());
                        continue;
                    }
                    let known = shared.known_now();
                    // The points the budget has left for this chunk go to its first
                    // rectangles, in order (a rectangle further on gives up, as one past the
                    // budget does), not to whichever lanes ask first, so that which rectangles
                    // are sampled does not depend on the threads either.
                    let left = shared.points_left();
                    let lanes: Vec<Vec<Outcome>> = chunk
                        .par_chunks(lane_len)
                        .enumerate()
                        .map(|(l, lane)| {
                            let mut known = known.clone();
                            let Some(mut r) = pool.take(new_renderer) else {
                                // No renderer (the device failed): what the lane would test
                                // stays visible.
                                for &i in lane {
                                    shared.give_up(&level[i].1, &mut known);
                                }
                                return vec![(None, RectRecord::default()); lane.len()];
                            };
                            let open = lane
                                .iter()
                                .enumerate()
                                .map(|(k, &i)| {
                                    let mut rec = RectRecord::default();
                                    let o = shared.patch(
                                        &mut r,
                                        level[i].0,
                                        &level[i].1,
                                        &mut known,
                                        &mut rec,
                                        Take::Point(((l * lane_len + k) as u64) < left),
                                    );
                                    shared.count(&rec);
                                    (o, rec)
                                })
                                .collect();
                            pool.give(r);
                            open
                        })
                        .collect();
                    let results: Vec<_> = lanes.into_iter().flatten().collect();
                    if let Some(c) = &ckpt
                        && !shared.has_failed()
                    {
                        let recs = chunk.iter().zip(&results).map(|(&i, (o, rec))| {
                            let mut rec = rec.clone();
                            rec.open = o.as_ref().map(|l| l.to_vec());
                            (i, rec)
                        });
                        let seconds = shared.start.elapsed().as_secs_f64();
                        match c.record(this_level, recs, || shared.known_now(), seconds) {
                            Ok(false) => {}
                            Ok(true) => {
                                *ckpt_failed.lock().unwrap_or_else(|e| e.into_inner()) =
                                    Some(BakeError::Interrupted);
                            }
                            Err(e) => {
                                *ckpt_failed.lock().unwrap_or_else(|e| e.into_inner()) = Some(e);
                            }
                        }
                    }
                    out.extend(results.into_iter().map(|(o, _)| o));
                    rects_done(chunk.len());
                }
                out
            };
            // Every level but the finest starts with a probe of its rectangles; when that
            // proves too little the rest is split unsampled (their quadrants inherit every
            // candidate, as for `--sampling-max-eps`).
            let finest_level = level_eps <= finest_eps * (1.0 + 1e-6);
            let stride = probe_stride(level.len());
            let mut open: Vec<Option<Arc<Vec<u32>>>> = vec![None; level.len()];
            let mut probe_only = false;
            let mut probe_hidden = None;
            let mut probe_cell = None;
            let mut probe_cost = None;
            let mut pilot_saving = None;
            let mut probe_rects = None;
            if s.probe > 0.0 && !finest_level && stride > 1 {
                // Every `stride`-th rectangle, the faces in turn, in rounds.
                let probe = faces_in_turn((0..level.len()).step_by(stride).collect(), |i| {
                    level[i].0.face
                });
                let (t0, h0) = (
                    shared.tested.load(Ordering::Relaxed),
                    shared.hid.load(Ordering::Relaxed),
                );
                // Per-rectangle hides add up to a cull only for an object hidden at every
                // rectangle that tests it: unless some object still undecided was hidden at
                // every probed rectangle that tested it, the rest of the level will rarely cull
                // anything (it mostly prunes the next level's lists). Only an object that no
                // probed rectangle tests escapes this guess; unsampled rectangles pass every
                // candidate on, so it costs points, never soundness.
                // `seen`: 1, in a probed rectangle's list; 2, left open by one.
                let mut seen = vec![0u8; n];
                // Rounds a resumed probe goes on after without asking (see below).
                let go_on = ckpt
                    .as_ref()
                    .map_or(0, |c| c.with_level(this_level, |l| l.probe_rounds));
                let mut probed = 0;
                let mut rounds = 0u32;
                while probed < probe.len() {
                    let round = &probe[probed..(probed + PROBE_ROUND).min(probe.len())];
                    for (&i, o) in round.iter().zip(sample(round)) {
                        open[i] = o;
                    }
                    for &i in round {
                        for &o in level[i].1.iter() {
                            seen[o as usize] |= 1;
                        }
                        for &o in open[i].iter().flat_map(|l| l.iter()) {
                            seen[o as usize] |= 2;
                        }
                    }
                    probed += round.len();
                    if probed == probe.len() || stopped() || shared.has_failed() {
                        continue;
                    }
                    // The probe stops early when its rest could prove nothing: every object
                    // still undecided that it tested was left open by some probed rectangle
                    // (that stays so), and the rectangles left test no undecided object it
                    // has not. Then the whole probe would prove nothing either, so the level
                    // is split unsampled all the same (the decision below), sooner. A resumed
                    // probe goes on after the rounds its interrupted run went on after (the
                    // objects known visible then, which this asks, are not in the file; after
                    // the last recorded round they are the file's).
                    if rounds >= go_on
                        && !shared.spent()
                        && probe_can_stop(
                            &seen,
                            |o| !shared.done[o as usize].load(Ordering::Relaxed),
                            probe[probed..].iter().map(|&i| &level[i].1[..]),
                        )
                    {
                        break;
                    }
                    rounds += 1;
                    if let Some(c) = &ckpt {
                        c.with_level(this_level, |l| l.probe_rounds = l.probe_rounds.max(rounds));
                    }
                }
                let probe = &probe[..probed];
                let tested = shared.tested.load(Ordering::Relaxed) - t0;
                let hid = shared.hid.load(Ordering::Relaxed) - h0;
                probe_hidden = (tested > 0).then(|| hid as f64 / tested as f64);
                probe_rects = Some(probed as u32);
                // Objects still undecided that the probe tested, and those of them that every
                // probed rectangle testing them hid (the level's cull, had it been only its
                // probe).
                let (mut probe_tested, mut probe_all_hid) = (0u32, 0u32);
                for (o, &f) in seen.iter().enumerate() {
                    if f != 0 && !shared.done[o].load(Ordering::Relaxed) {
                        probe_tested += 1;
                        probe_all_hid += u32::from(f == 1);
                    }
                }
                probe_cell = Some((probe_all_hid, probe_tested));
                // ... and unless enough of them were, the level's balls do not fuse the
                // occluders: its points cost far more than the finest level's and prune it
                // little (`SamplingSettings::probe_cull`).
                let may_cull = probe_all_hid > 0
                    && f64::from(probe_all_hid) >= s.probe_cull * f64::from(probe_tested);
                let mut in_probe = vec![false; level.len()];
                for &i in probe {
                    in_probe[i] = true;
                }
                let rest: Vec<usize> = (0..level.len()).filter(|&i| !in_probe[i]).collect();
                // A resumed level keeps the decision its interrupted run made.
                let resumed = ckpt.as_ref().and_then(|c| {
                    c.with_level(this_level, |l| {
                        l.probe_only.map(|p| (p, l.pilot, l.probe_cell))
                    })
                });
                let skip = match resumed {
                    Some((skip, pilot, cell)) => {
                        (probe_cost, pilot_saving) = (pilot.map(|p| p.0), pilot.map(|p| p.1));
                        // Counted when the decision was made: objects found visible after it
                        // (in the file's known set) would leave this count.
                        probe_cell = cell.or(probe_cell);
                        skip
                    }
                    None => {
                        let proves_little = (hid as f64) < s.probe * tested as f64 || !may_cull;
                        // The level just above the finest must also save the finest level
                        // more than it costs (`SamplingSettings::probe_pay`).
                        let above_finest = level_eps * 0.5 <= finest_eps * (1.0 + 1e-6);
                        // (Not in a cell already failing: its lists are not results.)
                        let failing = stopped() || shared.has_failed();
                        if !proves_little
                            && above_finest
                            && s.probe_pay > 0.0
                            && !shared.spent()
                            && !failing
                        {
                            let finest_res = level_resolution(finest_eps);
                            // The pilot's hemicubes replace the level's (one per thread).
                            pool.clear();
                            let (cost, saving) =
                                shared.pilot(&level, &open, probe, resolution, finest_res);
                            (probe_cost, pilot_saving) = (Some(cost), Some(saving));
                        }
                        let too_dear = probe_cost
                            .zip(pilot_saving)
                            .is_some_and(|(cost, saving)| saving < s.probe_pay * cost);
                        (proves_little || too_dear) && !shared.spent()
                    }
                };
                if let Some(c) = &ckpt {
                    c.with_level(this_level, |l| {
                        l.probe_only = Some(skip);
                        l.probe_cell = probe_cell;
                        l.pilot = probe_cost.zip(pilot_saving);
                    });
                }
                if skip {
                    probe_only = true;
                    // Their quadrants drop what was decided meanwhile (`patch` filters).
                    rects_done(rest.len());
                    for i in rest {
                        open[i] = Some(level[i].1.clone());
                    }
                } else {
                    for (i, o) in rest.iter().zip(sample(&rest)) {
                        open[*i] = o;
                    }
                }
            } else {
                // Scouts first, every 16th rectangle: what they find visible spares all the
                // lanes after them (lanes share only at their chunk's start).
                let scouts: Vec<usize> = (0..level.len()).step_by(SCOUT_STRIDE).collect();
                let rest: Vec<usize> = (0..level.len()).filter(|i| i % SCOUT_STRIDE != 0).collect();
                for (&i, o) in scouts.iter().zip(sample(&scouts)) {
                    open[i] = o;
                }
                for (&i, o) in rest.iter().zip(sample(&rest)) {
                    open[i] = o;
                }
            }
            // The cost curve: what a budget that ran out here would have culled.
            undecided.fill(false);
            for &o in open.iter().flatten().flat_map(|l| l.iter()) {
                undecided[o as usize] = true;
            }
            let entry = SamplingLevel {
                eps: level_eps,
                resolution,
                points: shared.points.load(Ordering::Relaxed),
                seconds: shared.start.elapsed().as_secs_f64(),
                hidden: candidates
                    .iter()
                    .filter(|&&o| {
                        !undecided[o as usize] && !shared.done[o as usize].load(Ordering::Relaxed)
                    })
                    .count() as u32,
                probe_only,
                probe_hidden,
                probe_cell_hidden: probe_cell.map(|(h, _)| h),
                probe_objects: probe_cell.map(|(_, t)| t),
                probe_rects,
                probe_cost,
                pilot_saving,
            };
            // A level its interrupted run finished keeps the entry it made then.
            let entry = match &ckpt {
                Some(c) => c.with_level(this_level, |l| *l.curve.get_or_insert(entry)),
                None => entry,
            };
            curve.push(entry);
            if shared.spent() {
                // The next level would sample nothing: what it would test stays visible.
                for l in open.iter().flatten() {
                    shared.mark_visible(l);
                }
                break;
            }
            // The next level: each rectangle left with undecided objects split in four, but
            // no more than `SPLIT_PER_POINT_LEFT` per point the budget has left. A level far
            // beyond the budget (a tiny ε, levels split unsampled one after another) would
            // otherwise hold millions of rectangles that can never be sampled (6 GB for a
            // wall with a window 1e-6 across); those past the cap give their objects up now,
            // as the budget would when it reached them. (Not filtered by what is decided: a
            // resumed run knows the cut's visible objects here, and would split otherwise.)
            let left = shared.points_left();
            let cap = left.saturating_mul(SPLIT_PER_POINT_LEFT).max(64);
            let mut next = Vec::new();
            for ((patch, _), open) in level.iter().zip(open) {
                let Some(o) = open else { continue };
                if next.len() as u64 + 4 > cap {
                    shared.mark_visible(&o);
                    continue;
                }
                next.extend(patch.quadrants().map(|q| (q, o.clone())));
            }
            level = next;
        }
        if let Some(e) = shared
            .failed
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take()
        {
            return Err(e.into());
        }
        if let Some(e) = ckpt_failed.into_inner().unwrap_or_else(|e| e.into_inner()) {
            return Err(e);
        }
        if let Some(c) = &ckpt {
            c.finish(|| shared.known_now(), shared.start.elapsed().as_secs_f64())?;
        }
        for &o in &candidates {
            if !shared.done[o as usize].load(Ordering::Relaxed) {
                state.hidden[o as usize] = true;
            }
        }
        let finest = f64::from_bits(shared.finest.load(Ordering::Relaxed));
        let cpu_fallback = shared
            .fallback
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take();
        Ok(CullerWork {
            points: shared.points.load(Ordering::Relaxed),
            polygons: shared.polygons.load(Ordering::Relaxed),
            finest_eps: finest.is_finite().then_some(finest),
            levels: curve,
            cpu_fallback,
            resumed_ms: resumed.as_ref().map_or(0.0, |r| r.seconds * 1e3),
            ..CullerWork::default()
        })
    }
}

/// How a rectangle stands with the budget ([`Shared::patch`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Take {
    /// It may take a sample point (false: the points its chunk had left went to the
    /// rectangles before it; it gives up as one past the budget does).
    Point(bool),
    /// A trial render (a level's pilot): no point taken, nothing given up.
    Trial,
}

/// One candidate's result in a render for its group ([`Shared::render_group`]).
enum GroupTest {
    /// Known visible before the test (certified by a ray of the rectangle's): not tested.
    Known,
    /// Hidden from every point of the rectangle.
    Hidden,
    /// Open: a direction in which it may show.
    Open(DVec3),
}

/// The candidates' indices grouped by their boxes' farthest distance from `eye`: each group's
/// farthest distance is at most `ratio` times the nearest of them (bands `(f·ratio^k,
/// f·ratio^(k+1)]` above the nearest, `f`), nearest group first. With `ratio` 0, one group.
/// [`Hemicube::begin_patch`] shrinks each group's render only as much as its farthest box
/// needs.
fn distance_bands(eye: DVec3, boxes: &[DAabb], ratio: f64) -> Vec<Vec<usize>> {
    if ratio <= 1.0 || boxes.len() < 2 {
        return vec![(0..boxes.len()).collect()];
    }
    let far: Vec<f64> = boxes
        .iter()
        .map(|b| (b.min - eye).abs().max((b.max - eye).abs()).length())
        .collect();
    let nearest = far.iter().copied().fold(f64::INFINITY, f64::min).max(1e-9);
    let lr = ratio.ln();
    let mut bands: Vec<Vec<usize>> = Vec::new();
    for (i, &f) in far.iter().enumerate() {
        let k = ((f / nearest).ln() / lr).max(0.0) as usize;
        if bands.len() <= k {
            bands.resize_with(k + 1, Vec::new);
        }
        bands[k].push(i);
    }
    bands.retain(|b| !b.is_empty());
    bands
}

/// The top-level grid of a face `wb` × `wc` wide: rectangles whose half diagonals are at
/// most `eps0`.
fn face_grid(wb: f64, wc: f64, eps0: f64) -> (usize, usize) {
    let side = eps0 * std::f64::consts::SQRT_2;
    (
        (wb / side).ceil().max(1.0) as usize,
        (wc / side).ceil().max(1.0) as usize,
    )
}

/// The top level's ε for a cell whose finest is `eps`: `levels` doublings above it, and more
/// while the six faces' top-level rectangles would outnumber `budget` sample points. A tiny ε
/// (given, or chosen from occluders that are mostly slivers) would otherwise lay millions of
/// rectangles at once, more than the budget can ever render and more memory than the machine
/// has; the coarser levels above it are split only where objects stay undecided.
pub fn top_eps(cell: &DAabb, eps: f64, levels: u32, budget: u64) -> f64 {
    let mut eps0 = eps * f64::from(1u32 << levels.min(20));
    let top = |e: f64| {
        (0..3).fold(0u64, |sum, axis| {
            let (b, c) = ((axis + 1) % 3, (axis + 2) % 3);
            let (nb, nc) = face_grid(cell.max[b] - cell.min[b], cell.max[c] - cell.min[c], e);
            sum.saturating_add((nb as u64).saturating_mul(nc as u64).saturating_mul(2))
        })
    };
    while top(eps0) > budget.max(6) {
        eps0 *= 2.0;
    }
    eps0
}

/// The rectangles of `cell`'s finest level if every one were refined down to it (finest ε
/// `eps`, `levels` levels above it): the most points the sampler can render for the cell,
/// about its boundary's area / (2ε²). Shown by `bake` so that a slow sampler is expected.
pub fn finest_rectangles(cell: &DAabb, eps: f64, levels: u32) -> u64 {
    let eps0 = eps * f64::from(1u32 << levels.min(20));
    let mut total = 0u64;
    for axis in 0..3 {
        let (b, c) = ((axis + 1) % 3, (axis + 2) % 3);
        let (wb, wc) = (cell.max[b] - cell.min[b], cell.max[c] - cell.min[c]);
        let (nb, nc) = face_grid(wb, wc, eps0);
        // Quadrants halve the half diagonal until it is the finest ε.
        let mut half = 0.5 * (wb / nb as f64).hypot(wc / nc as f64);
        let mut per_top = 1u64;
        while half > eps * (1.0 + 1e-6) && per_top < 1 << 40 {
            half *= 0.5;
            per_top *= 4;
        }
        total = total.saturating_add(
            (nb as u64)
                .saturating_mul(nc as u64)
                .saturating_mul(2 * per_top),
        );
    }
    total
}

/// The stride of a level's probe of `n` rectangles (every `stride`-th is probed): every
/// [`SamplingSettings::PROBE_STRIDE`]-th, but at least [`SamplingSettings::PROBE_MIN`]
/// rectangles and about [`SamplingSettings::PROBE_MAX`] at most; 1 (all of them, no probe)
/// when there are too few.
fn probe_stride(n: usize) -> usize {
    (n / SamplingSettings::PROBE_MAX)
        .max(SamplingSettings::PROBE_STRIDE)
        .min(n / SamplingSettings::PROBE_MIN)
        .max(1)
}

/// A level is split into at most this many rectangles per sample point the budget has left
/// (`--sampling-budget`); the rest give their objects up at the split. Four: a rectangle
/// whose objects were all decided before its turn takes no point, and on the fine forest's
/// 4×2×4 cell a quarter of the finest level's rectangles take none (36,931 points for
/// 48,384), so a level up to four times the points left may still be sampled whole.
const SPLIT_PER_POINT_LEFT: u64 = 4;

/// A level sampled whole starts with every this-many-th rectangle.
const SCOUT_STRIDE: usize = 16;
/// A level's probe samples this many rectangles at a time, then asks whether the rest could
/// prove anything. Fixed, never the thread count, so that where it stops does not depend on
/// the machine. Eight is more than one per face.
///
/// On the fine forest's middle 4×2×4 cell (`bake --sweep --sampling --backend cpu
/// --sampling-budget 2400`, two cores) the level at ε 0.118 stops after 3 rounds instead of
/// 64 rectangles, 68 s → 30 s (`docs/sampling.md`, "Probes that stop early").
const PROBE_ROUND: usize = 8;

/// Whether a level's probe can stop before the rectangles whose candidate lists `rest` gives:
/// every object `undecided` that it tested (`seen[o]` 1: in a probed rectangle's list) was
/// left open by some probed rectangle (`seen[o]` 3), and no list of the rest holds an object
/// `undecided` that it has not tested (`seen[o]` 0). Then no object undecided at the end can
/// be hidden at every probed rectangle testing it, however many more it probes (an object
/// left open stays so, and objects only leave the undecided), so the whole probe would prove
/// nothing for the cell either.
fn probe_can_stop<'a>(
    seen: &[u8],
    undecided: impl Fn(u32) -> bool,
    mut rest: impl Iterator<Item = &'a [u32]>,
) -> bool {
    let all_open = !(0..seen.len() as u32).any(|o| seen[o as usize] == 1 && undecided(o));
    all_open && !rest.any(|l| l.iter().any(|&o| seen[o as usize] == 0 && undecided(o)))
}

/// `probe` (rectangle indices, each face's in order) reordered so that the faces take turns:
/// the first rectangle of each face, then the second of each, and so on (faces in the order
/// they first appear). A probe's first rounds then test every face's objects.
fn faces_in_turn(probe: Vec<usize>, face: impl Fn(usize) -> usize) -> Vec<usize> {
    let mut by_face: Vec<(usize, Vec<usize>)> = Vec::new();
    for i in probe {
        let f = face(i);
        match by_face.iter_mut().find(|(g, _)| *g == f) {
            Some((_, l)) => l.push(i),
            None => by_face.push((f, vec![i])),
        }
    }
    let longest = by_face.iter().map(|(_, l)| l.len()).max().unwrap_or(0);
    (0..longest)
        .flat_map(|k| by_face.iter().filter_map(move |(_, l)| l.get(k).copied()))
        .collect()
}

/// A level's pilot ([`Shared::pilot`]) renders at most this many of its probed rectangles
/// again, and one quadrant of each twice.
const PILOT_RECTS: usize = 8;

/// Lanes per chunk of rectangles at most ([`lanes`]).
const LANES: usize = 16;
/// Rectangles per lane at most ([`lanes`]).
const LANE_MAX: usize = 32;

/// How `n` rectangles sampled together are cut: chunks of the returned length (the last may
/// be shorter), each in up to [`LANES`] lanes of the returned length, as even as can be.
/// Fixed by `n` alone, never by the thread count, so the sampler's results are the same on any
/// number of threads. Within a lane what one rectangle finds visible (certified by its rays,
/// or given up at the finest ε) spares the next at once; across lanes from the next chunk on.
///
/// Measured on the coarse forest's middle 1×1×1 cell (`bake --sampling --sampling-eps
/// 0.044`, CPU, two cores, one bake each): when every rectangle saw at once what any other
/// found (results depending on the threads), 2,116 points, 118 and 136 s, 664 objects hidden
/// by the sampler; with one rectangle per lane (nothing shared within a chunk), 1,810 points,
/// 147 s; with these lanes, 1,972 points, 140 s, 664 hidden; with the scouts first
/// ([`SCOUT_STRIDE`]), 1,809 points, 124 s, 662 hidden.
fn lanes(n: usize) -> (usize, usize) {
    let chunks = n.div_ceil(LANES * LANE_MAX).max(1);
    let chunk = n.div_ceil(chunks).max(1);
    (chunk, chunk.div_ceil(LANES))
}

/// Rays [`median_hit_distance`] casts per cell.
const HIT_RAYS: usize = 4096;
/// The phase of [`median_hit_distance`]'s ray stream.
const HIT_PHASE: u64 = 0x5eed;

/// The median distance at which rays from random points of `cell` in random directions first
/// hit a blocking triangle (rays that hit nothing left out), or NaN when none hits: the scale
/// of the automatic sampling resolution ([`SamplingSettings::auto_resolution`]). Deterministic
/// per cell (`seed`).
fn median_hit_distance(rays: &SceneRays, cell: &Aabb, seed: u64, alpha_blocks: bool) -> f64 {
    // The validator's ray streams (its phases are small numbers; this one is its own).
    let mut rng = crate::validate::chunk_rng(seed, 0, HIT_PHASE, 0);
    let mut hits: Vec<f32> = Vec::with_capacity(HIT_RAYS);
    for _ in 0..HIT_RAYS {
        let origin = crate::validate::uniform_origin(&mut rng, cell);
        let direction = crate::validate::sphere_direction(&mut rng).as_vec3();
        if let Some(h) = rays.trace(origin, direction, alpha_blocks).last() {
            hits.push(h.t * direction.length());
        }
    }
    if hits.is_empty() {
        return f64::NAN;
    }
    let mid = hits.len() / 2;
    f64::from(*hits.select_nth_unstable_by(mid, f32::total_cmp).1)
}

/// A seed for the cell's certifying rays, from its coordinates (same cell, same rays).
fn cell_seed(cell: &Aabb) -> u64 {
    let mut h: u64 = 0x9e37_79b9_7f4a_7c15;
    for v in cell.min.to_array().into_iter().chain(cell.max.to_array()) {
        h = (h ^ u64::from(v.to_bits())).wrapping_mul(0x0100_0000_01b3);
        h ^= h >> 29;
    }
    h
}

impl Shared<'_> {
    /// Sample points the budget has left (`--sampling-budget` in points).
    fn points_left(&self) -> u64 {
        (self.data.settings.budget_points).saturating_sub(self.points.load(Ordering::Relaxed))
    }

    /// Whether the budget is spent (no point can be taken).
    fn spent(&self) -> bool {
        let s = &self.data.settings;
        self.points.load(Ordering::Relaxed) >= s.budget_points || !self.in_time()
    }

    fn in_time(&self) -> bool {
        (self.data.settings.budget_seconds).is_none_or(|t| self.start.elapsed().as_secs_f64() < t)
    }

    /// Takes one sample point from the budget; false (and nothing taken) when it is spent.
    fn take_point(&self) -> bool {
        let s = &self.data.settings;
        if !self.in_time() {
            return false;
        }
        if self.points.fetch_add(1, Ordering::Relaxed) >= s.budget_points {
            self.points.fetch_sub(1, Ordering::Relaxed);
            return false;
        }
        if let Some(p) = self.prepared.sampler_progress {
            p.points.fetch_add(1, Ordering::Relaxed);
        }
        true
    }

    /// Adds a sampled rectangle's object tests, hides and polygons drawn to the cell's
    /// totals (a level's probe compares the first two; trials are never counted).
    fn count(&self, r: &RectRecord) {
        self.tested.fetch_add(r.tested, Ordering::Relaxed);
        self.hid.fetch_add(r.hid, Ordering::Relaxed);
        self.polygons.fetch_add(r.polygons, Ordering::Relaxed);
    }

    /// Adds what a recorded rectangle counted (a replayed checkpoint) to the totals, as
    /// [`Shared::patch`] did when it sampled it.
    fn replay(&self, patch: Patch, r: &RectRecord) {
        self.count(r);
        if r.point {
            self.points.fetch_add(1, Ordering::Relaxed);
            if let Some(p) = self.prepared.sampler_progress {
                p.points.fetch_add(1, Ordering::Relaxed);
            }
            let eps = patch.ball_eps();
            self.finest.fetch_min(eps.to_bits(), Ordering::Relaxed);
        }
    }

    /// A snapshot of the objects known visible now.
    fn known_now(&self) -> Vec<bool> {
        self.done
            .iter()
            .map(|d| d.load(Ordering::Relaxed))
            .collect()
    }

    /// Marks `list` visible (undecided at the finest ε, or out of budget) in the live set.
    fn mark_visible(&self, list: &[u32]) {
        for &o in list {
            self.done[o as usize].store(true, Ordering::Relaxed);
        }
    }

    /// Records the first reason a GPU sampler was replaced by the CPU's hemicube.
    fn fall_back(&self, resolution: u32, e: &BackendError) {
        let mut f = self.fallback.lock().unwrap_or_else(|e| e.into_inner());
        if f.is_none() {
            *f = Some(format!(
                "the device could not make a GPU sampler at {resolution} px: {e}"
            ));
        }
    }

    /// Whether a device failure was recorded ([`Shared::fail`]).
    fn has_failed(&self) -> bool {
        self.failed
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .is_some()
    }

    /// Records the first device failure.
    fn fail(&self, e: BackendError) {
        let mut f = self.failed.lock().unwrap_or_else(|e| e.into_inner());
        if f.is_none() {
            *f = Some(e);
        }
    }

    /// [`Shared::mark_visible`], and in the lane's `known`.
    fn give_up(&self, list: &[u32], known: &mut [bool]) {
        self.mark_visible(list);
        for &o in list {
            known[o as usize] = true;
        }
    }

    /// Samples one patch. Returns the objects still undecided there when its quadrants should
    /// be sampled for them (none: all decided, or given up at the finest ε or the budget).
    ///
    /// `known` is its lane's view of what is known visible (what was when the chunk began,
    /// and what the lane found since): the rectangle decides with it, not with the live set
    /// that other lanes update meanwhile, so that its result is the same whatever runs beside
    /// it, and adds to it what it finds visible.
    ///
    /// `take` says whether it may take a point of the budget ([`Take`]); a trial (a level's
    /// pilot, [`Shared::pilot`]) renders and tests as the rectangle would but takes no point
    /// of the budget and gives nothing up: what it leaves open at the finest ε stays
    /// undecided (only its counts in `rec` are used).
    fn patch(
        &self,
        renderer: &mut Renderer,
        patch: Patch,
        list: &[u32],
        known: &mut [bool],
        rec: &mut RectRecord,
        take: Take,
    ) -> Option<Arc<Vec<u32>>> {
        let trial = take == Take::Trial;
        let list: Vec<u32> = list
            .iter()
            .copied()
            .filter(|&o| !known[o as usize])
            .collect();
        if list.is_empty() {
            return None;
        }
        if let Take::Point(allowed) = take {
            if !allowed || !self.take_point() {
                self.give_up(&list, known);
                return None;
            }
            rec.point = true;
        }
        let f = self.faces[patch.face];
        let (b, c) = ((f.axis + 1) % 3, (f.axis + 2) % 3);
        let mut eye = DVec3::ZERO;
        eye[f.axis] = f.plane;
        eye[b] = 0.5 * (patch.b[0] + patch.b[1]);
        eye[c] = 0.5 * (patch.c[0] + patch.c[1]);
        let (hb, hcx) = patch.half_sides();
        let eps = patch.ball_eps();
        if !trial {
            self.finest.fetch_min(eps.to_bits(), Ordering::Relaxed);
        }
        let scene = self.prepared.scene;
        let boxes: Vec<DAabb> = list
            .iter()
            .map(|&o| scene.objects[o as usize].bounds.to_f64())
            .collect();
        let half = [hb * (1.0 + 1e-9), hcx * (1.0 + 1e-9)];
        let mut open: Vec<u32> = Vec::new();
        let mut rays = 0usize;
        if let Renderer::Sweep(sw) = renderer {
            self.sweep_patch(sw, eye, &f, half, &list, &boxes, known, rec, &mut open);
            return self.patch_outcome(open, known, eps, trial);
        }
        let ratio = self.data.settings.band_ratio;
        let bands = distance_bands(eye, &boxes, ratio);
        // One render for the whole list first, its edges shrunk for the farthest box (a
        // render's shrinks hold for every occludee no farther): what it hides is decided, and
        // only what it leaves open goes to the bands, formed over those alone (the bands do
        // not count them as tested again).
        let first = bands.len() > 1 && self.data.settings.whole_first;
        let bands = if first {
            let all: Vec<usize> = (0..list.len()).collect();
            let tests = self.render_group(
                renderer, eye, &f, half, &list, &boxes, &all, known, rec, true,
            )?;
            let left: Vec<usize> = all
                .into_iter()
                .zip(tests)
                .filter(|(_, t)| matches!(t, GroupTest::Open(_)))
                .map(|(i, _)| i)
                .collect();
            let left_boxes: Vec<DAabb> = left.iter().map(|&i| boxes[i]).collect();
            distance_bands(eye, &left_boxes, ratio)
                .into_iter()
                .map(|b| b.into_iter().map(|k| left[k]).collect())
                .collect()
        } else {
            bands
        };
        for band in bands {
            let tests = self.render_group(
                renderer, eye, &f, half, &list, &boxes, &band, known, rec, !first,
            )?;
            for (&i, test) in band.iter().zip(tests) {
                let o = list[i];
                let GroupTest::Open(direction) = test else {
                    continue;
                };
                // Undecided here: try to certify it with real rays from the eye.
                if rays < CERTIFY_PER_POINT {
                    rays += self.certify(eye, o, direction, known);
                }
                if !known[o as usize] {
                    open.push(o);
                }
            }
        }
        self.patch_outcome(open, known, eps, trial)
    }

    /// What a rectangle of ball radius `eps` leaves its quadrants: the objects it found open
    /// and no ray certified since, unless it is at the finest ε (then they are given up,
    /// visible for the cell, except in a trial).
    fn patch_outcome(
        &self,
        mut open: Vec<u32>,
        known: &mut [bool],
        eps: f64,
        trial: bool,
    ) -> Option<Arc<Vec<u32>>> {
        // Certification may have reached objects found open earlier.
        open.retain(|&o| !known[o as usize]);
        if open.is_empty() {
            return None;
        }
        if eps <= self.finest_eps * (1.0 + 1e-6) {
            if !trial {
                self.give_up(&open, known);
            }
            return None;
        }
        Some(Arc::new(open))
    }

    /// [`Shared::patch`] with the per-rectangle sweep: one render decides every candidate
    /// (`list`, boxes `boxes`), each tested when the sweep reaches it (its box, then its
    /// pieces' boxes and triangles, as [`Shared::test_object`] does). Open objects are
    /// certified with rays (towards their box's centre) and appended to `open`.
    #[expect(
        clippy::too_many_arguments,
        reason = "the rectangle (eye, face, half sides), its lists and the lane's state, as render_group"
    )]
    fn sweep_patch(
        &self,
        sw: &mut RectSweep,
        eye: DVec3,
        f: &Face,
        half: [f64; 2],
        list: &[u32],
        boxes: &[DAabb],
        known: &mut [bool],
        rec: &mut RectRecord,
        open: &mut Vec<u32>,
    ) {
        let objects = SweepObjects {
            prepared: self.prepared,
            list,
            boxes,
        };
        let (hidden, st) = sw.render(&self.data.occluders, eye, f.axis, f.sign, half, &objects);
        rec.polygons += st.polygons;
        let mut rays = 0usize;
        for (i, &o) in list.iter().enumerate() {
            if known[o as usize] {
                continue;
            }
            rec.tested += 1;
            if hidden[i] {
                rec.hid += 1;
                continue;
            }
            if rays < CERTIFY_PER_POINT {
                rays += self.certify(eye, o, boxes[i].center() - eye, known);
            }
            if !known[o as usize] {
                open.push(o);
            }
        }
    }

    /// The pilot of the level just above the finest ([`SamplingSettings::probe_pay`]): what
    /// sampling one more of the level's rectangles costs and what it is expected to save the
    /// finest level, both in polygons drawn weighted by resolution
    /// ([`SamplingSettings::polygon_weight`]; the level's `resolution`, the finest level's
    /// `finest_res`). For up to [`PILOT_RECTS`] of the probed rectangles (`probe`, indices
    /// into `level`; `open`, what each left open) it renders as trials the rectangle itself,
    /// with its candidates, and one of its quadrants (a rectangle of the finest level) twice:
    /// with the candidates it inherits if the rest of the level is split unsampled, and with
    /// what the probed rectangle left open (nothing to render when that left nothing). The
    /// saving is four times the quadrant's difference. (Coarser levels save the finest level
    /// through the levels between, which such trials cannot see: they have no pilot.) Trials
    /// render on the CPU's hemicube whatever the backend,
    /// from one snapshot of what is known visible, so the estimate depends only on the
    /// level's results, never on the backend, threads or timing, and none of it counts as
    /// the cell's points or polygons. Runs while no lane renders. Returns the means per
    /// rectangle `(cost, saving)`.
    fn pilot(
        &self,
        level: &[(Patch, Arc<Vec<u32>>)],
        open: &[Option<Arc<Vec<u32>>>],
        probe: &[usize],
        resolution: u32,
        finest_res: u32,
    ) -> (f64, f64) {
        let step = probe.len().div_ceil(PILOT_RECTS).max(1);
        let picks: Vec<usize> = probe.iter().copied().step_by(step).collect();
        if picks.is_empty() {
            return (0.0, 0.0);
        }
        let known = self.known_now();
        let settings = self.data.settings;
        // One hemicube per thread at a time (made again when the resolution changes), as
        // the bake's memory estimate allows. Trials are not sample points: nothing of theirs
        // is counted in the cell's totals (a resumed cell that replays the decision renders
        // none).
        let drawn = |slot: &mut Option<(u32, Renderer)>, res: u32, q: Patch, list: &[u32]| {
            if slot.as_ref().is_some_and(|(r, _)| *r != res) {
                *slot = None;
            }
            let (_, r) = slot.get_or_insert_with(|| (res, Renderer::cpu(res, &settings)));
            let mut rec = RectRecord::default();
            self.patch(r, q, list, &mut known.clone(), &mut rec, Take::Trial);
            rec.polygons as f64
        };
        let (wl, wf) = (
            SamplingSettings::polygon_weight(resolution),
            SamplingSettings::polygon_weight(finest_res),
        );
        let each: Vec<(f64, f64)> = picks
            .par_iter()
            .map_init(
                || None,
                |slot, &i| {
                    // One quadrant (which one varies with the rectangle).
                    let q = level[i].0.quadrants().nth(i % 4).unwrap_or(level[i].0);
                    let cost = drawn(slot, resolution, level[i].0, &level[i].1);
                    let skipped = drawn(slot, finest_res, q, &level[i].1);
                    let kept = open[i]
                        .as_deref()
                        .map_or(0.0, |l| drawn(slot, finest_res, q, l));
                    (cost * wl, 4.0 * (skipped - kept) * wf)
                },
            )
            .collect();
        let m = each.len() as f64;
        (
            each.iter().map(|e| e.0).sum::<f64>() / m,
            each.iter().map(|e| e.1).sum::<f64>() / m,
        )
    }

    /// Renders for one group of a rectangle's candidates (`group`: indices into `list` and
    /// `boxes`, the render's edges shrunk for the farthest of them) and tests them, each
    /// object's result in the group's order (a hidden one counted as hidden at this
    /// rectangle). `count`: the objects tested also count as tested here (once per
    /// rectangle). `None` when the device failed: the rectangle then decides nothing (its
    /// list is given up).
    #[expect(
        clippy::too_many_arguments,
        reason = "a group's render needs the rectangle (eye, face, half sides), its lists and the lane's state; a struct would only move the list"
    )]
    fn render_group(
        &self,
        renderer: &mut Renderer,
        eye: DVec3,
        f: &Face,
        half: [f64; 2],
        list: &[u32],
        boxes: &[DAabb],
        group: &[usize],
        known: &mut [bool],
        rec: &mut RectRecord,
        count: bool,
    ) -> Option<Vec<GroupTest>> {
        let group_boxes: Vec<DAabb> = group.iter().map(|&i| boxes[i]).collect();
        // On the GPU the group's objects are tested together (boxes, then the open ones'
        // pieces, then the open pieces' triangles); on the CPU one by one as they come.
        let batch = match renderer {
            Renderer::Cpu(hc) => {
                hc.begin_patch(eye, f.axis, f.sign, half, &group_boxes);
                rec.polygons += hc.draw(&self.data.occluders).polygons;
                None
            }
            Renderer::Sweep(_) => unreachable!("Shared::patch renders the sweep by itself"),
            Renderer::Gpu(gs) => {
                gs.begin_patch(eye, f.axis, f.sign, half, &group_boxes);
                let objects: Vec<(u32, DAabb)> = group
                    .iter()
                    .filter(|&&i| !known[list[i] as usize])
                    .map(|&i| (list[i], boxes[i]))
                    .collect();
                match self.test_on_gpu(gs, eye, &objects) {
                    Ok(r) => {
                        rec.polygons += gs.last_draws();
                        Some(objects.iter().map(|p| p.0).zip(r).collect::<Vec<_>>())
                    }
                    Err(e) => {
                        // The device failed: this rectangle decides nothing.
                        self.fail(e);
                        self.give_up(list, known);
                        return None;
                    }
                }
            }
        };
        let mut batch = batch.map(|b| b.into_iter().peekable());
        let mut out = Vec::with_capacity(group.len());
        for &i in group {
            let (o, bx) = (list[i], &boxes[i]);
            // The GPU's answer for `o` (its batch holds the group's objects not known
            // visible when it ran, in the group's order).
            let from_gpu = batch
                .as_mut()
                .and_then(|b| b.next_if(|&(p, _)| p == o).map(|(_, r)| r));
            if known[o as usize] {
                // Certified visible by a ray of this rectangle's.
                out.push(GroupTest::Known);
                continue;
            }
            if count {
                rec.tested += 1;
            }
            let test = match (renderer as &Renderer, from_gpu) {
                (_, Some(r)) => r,
                (Renderer::Cpu(hc), None) => self.test_object(hc, o, bx),
                (Renderer::Gpu(_), None) => unreachable!("the batch holds every object"),
                (Renderer::Sweep(_), None) => unreachable!("never renders by group"),
            };
            out.push(match test {
                None => {
                    rec.hid += 1;
                    GroupTest::Hidden
                }
                Some(direction) => GroupTest::Open(direction),
            });
        }
        Some(out)
    }

    /// Tests object `o` (box `bx`) on the CPU: its box, and when that is open, its pieces
    /// ([`Shared::test_piece`]). None when hidden; else a direction in which it shows.
    fn test_object(&self, hc: &Hemicube, o: u32, bx: &DAabb) -> Option<DVec3> {
        match hc.test_box(bx) {
            BoxTest::Hidden => None,
            BoxTest::Open { direction } => {
                let pieces = self.prepared.pieces[o as usize].clone();
                if pieces.is_empty() {
                    return Some(direction);
                }
                for k in pieces {
                    if let BoxTest::Open { direction } = self.test_piece(hc, k as usize) {
                        return Some(direction);
                    }
                }
                None
            }
        }
    }

    /// Tests objects on the GPU as [`Shared::test_object`] does on the CPU, in three
    /// submissions: the boxes (with the render), the pieces of the open ones, the triangles
    /// of the open pieces. An object is hidden when its box is, or when it has pieces and each
    /// piece's box or every one of its triangles is: the CPU's answer, found by testing
    /// everything rather than stopping at the first open piece. An open object's direction
    /// is towards its box's centre (the GPU reads back no pixels).
    ///
    /// # Errors
    /// The device's failures.
    fn test_on_gpu(
        &self,
        gs: &mut GpuSampler,
        eye: DVec3,
        objects: &[(u32, DAabb)],
    ) -> Result<Vec<Option<DVec3>>, BackendError> {
        let p = self.prepared;
        let boxes: Vec<DAabb> = objects.iter().map(|&(_, b)| b).collect();
        let box_hidden = gs.test_boxes(&boxes)?;
        // The open objects' pieces.
        let mut pieces: Vec<(usize, usize)> = Vec::new();
        for (n, &(o, _)) in objects.iter().enumerate() {
            if !box_hidden[n] {
                pieces.extend(p.pieces[o as usize].clone().map(|k| (n, k as usize)));
            }
        }
        let piece_boxes: Vec<DAabb> = pieces.iter().map(|&(_, k)| p.piece_boxes[k]).collect();
        let mut piece_hidden = if piece_boxes.is_empty() {
            Vec::new()
        } else {
            gs.test_boxes(&piece_boxes)?
        };
        // The open pieces' triangles.
        let mut tris: Vec<[DVec3; 3]> = Vec::new();
        let mut tri_ids: Vec<u32> = Vec::new();
        let mut tri_piece: Vec<usize> = Vec::new();
        for (m, &(_, k)) in pieces.iter().enumerate() {
            if piece_hidden[m] {
                continue;
            }
            let r = &p.piece_triangle_ranges[k];
            for &t in &p.piece_triangles[r.start as usize..r.end as usize] {
                tris.push(p.scene.triangle(t as usize).map(|v| v.as_dvec3()));
                tri_ids.push(t);
                tri_piece.push(m);
            }
        }
        // A piece whose box is open is hidden when all its triangles are (as on the CPU, a
        // piece without any is).
        let mut all = vec![true; pieces.len()];
        if !tris.is_empty() {
            for (&m, h) in tri_piece
                .iter()
                .zip(gs.test_scene_triangles(&tri_ids, &tris)?)
            {
                all[m] &= h;
            }
        }
        for (h, a) in piece_hidden.iter_mut().zip(all) {
            *h |= a;
        }
        let mut open_piece = vec![false; objects.len()];
        for (m, &(n, _)) in pieces.iter().enumerate() {
            open_piece[n] |= !piece_hidden[m];
        }
        Ok(objects
            .iter()
            .enumerate()
            .map(|(n, &(o, bx))| {
                let hidden = box_hidden[n] || (!p.pieces[o as usize].is_empty() && !open_piece[n]);
                (!hidden).then(|| bx.center() - eye)
            })
            .collect())
    }

    /// Tests piece `k` of an object: its box, and when that is open, each of its triangles
    /// (whose union is the piece) pixel by pixel ([`Hemicube::test_triangle`]).
    fn test_piece(&self, hc: &Hemicube, k: usize) -> BoxTest {
        let p = self.prepared;
        let open = hc.test_box(&p.piece_boxes[k]);
        if open == BoxTest::Hidden {
            return open;
        }
        let scene = p.scene;
        for &t in &p.piece_triangles
            [p.piece_triangle_ranges[k].start as usize..p.piece_triangle_ranges[k].end as usize]
        {
            let tb = hc.test_triangle(scene.triangle(t as usize).map(|v| v.as_dvec3()));
            if tb != BoxTest::Hidden {
                return tb;
            }
        }
        BoxTest::Hidden
    }

    /// Casts up to [`CERTIFY_PER_OBJECT`] rays from `eye`: through the open pixel, and at a
    /// point of the object's surface. Marks every object they reach as visible, live and in
    /// the lane's `known`. Returns the rays cast.
    fn certify(&self, eye: DVec3, o: u32, direction: DVec3, known: &mut [bool]) -> usize {
        let rays = &self.data.rays;
        let origin = eye.as_vec3();
        let mut dirs = [Some(direction), None];
        let h =
            (eye.x.to_bits() ^ eye.y.to_bits().rotate_left(21) ^ eye.z.to_bits().rotate_left(42))
                .wrapping_mul(0x9e37_79b9_7f4a_7c15)
                ^ u64::from(o);
        let r = |k: u32| {
            ((h.rotate_left(k * 17).wrapping_mul(0xd1b5_4a32_d192_ed03)) >> 11) as f64
                / (1u64 << 53) as f64
        };
        dirs[1] = rays.surface_point(o, r(1), r(2), r(3)).map(|s| s - eye);
        let mut cast = 0;
        for d in dirs.into_iter().flatten().take(CERTIFY_PER_OBJECT) {
            let d = d.as_vec3();
            if !(d.length_squared() > 0.0 && d.is_finite()) {
                continue;
            }
            cast += 1;
            for hit in rays.trace(origin, d, self.prepared.settings.alpha_occluders) {
                self.done[hit.object as usize].store(true, Ordering::Relaxed);
                known[hit.object as usize] = true;
            }
        }
        cast
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A pool makes its first renderer whatever the budget, more only while the budget holds
    /// them (counting another level's), lanes beyond wait for one given back, and dropping it
    /// gives its bytes back.
    #[test]
    fn the_pool_keeps_to_its_budget_and_every_lane_gets_a_renderer() {
        let used = DeviceUse::default();
        let live = &used.live;
        // Another level holds 10 of the 35 bytes: two renderers of 10 fit, a third does not.
        let other = Pool::<u32>::new(10, 35, &used);
        assert_eq!(other.take(|| Some(0)), Some(0));
        let pool = Pool::<u32>::new(10, 35, &used);
        let holding = std::sync::atomic::AtomicUsize::new(0);
        let most = std::sync::atomic::AtomicUsize::new(0);
        let lanes = std::sync::atomic::AtomicUsize::new(0);
        std::thread::scope(|s| {
            for _ in 0..8 {
                s.spawn(|| {
                    for _ in 0..50 {
                        let r = pool.take(|| Some(7)).expect("a renderer");
                        let now = holding.fetch_add(1, Ordering::SeqCst) + 1;
                        most.fetch_max(now, Ordering::SeqCst);
                        std::thread::yield_now();
                        holding.fetch_sub(1, Ordering::SeqCst);
                        lanes.fetch_add(1, Ordering::SeqCst);
                        pool.give(r);
                    }
                });
            }
        });
        assert_eq!(lanes.load(Ordering::SeqCst), 400);
        assert_eq!(pool.made(), 2, "two fit beside the other level's one");
        assert_eq!(used.peak.load(Ordering::SeqCst), 30);
        assert!(most.load(Ordering::SeqCst) <= 2);
        assert_eq!(live.load(Ordering::SeqCst), 30);
        // Cleared (a pilot's turn), its renderers and their bytes are gone; the next take
        // makes a new one, within the budget again.
        pool.clear();
        assert_eq!(pool.made(), 0);
        assert_eq!(live.load(Ordering::SeqCst), 10);
        assert_eq!(pool.take(|| Some(9)), Some(9));
        assert_eq!(live.load(Ordering::SeqCst), 20);
        pool.give(9);
        drop(pool);
        assert_eq!(live.load(Ordering::SeqCst), 10);
        // Over budget already: a new level still makes its first, and only that.
        let big = Pool::<u32>::new(100, 35, &used);
        assert_eq!(big.take(|| Some(1)), Some(1));
        big.give(1);
        assert_eq!(big.take(|| Some(2)), Some(1));
        assert_eq!(big.made(), 1);
        assert_eq!(
            used.peak.load(Ordering::SeqCst),
            110,
            "the other's 10 and the first 100"
        );
        // A renderer that cannot be made is not counted.
        let failing = Pool::<u32>::new(5, 35, &used);
        assert_eq!(failing.take(|| None), None);
        assert_eq!(failing.made(), 0);
        drop((big, failing, other));
        assert_eq!(live.load(Ordering::SeqCst), 0);
    }

    /// [`probe_can_stop`]: only when every undecided object tested was left open somewhere
    /// and the rest tests none untested.
    #[test]
    fn a_probe_stops_only_when_its_rest_could_prove_nothing() {
        // Objects 0–4: 0 tested and left open, 1 tested and hidden everywhere so far, 2 not
        // tested, 3 tested and open, 4 not tested.
        let seen = [3u8, 1, 0, 3, 0];
        let all = |_: u32| true;
        let rest: [&[u32]; 2] = [&[0, 3], &[3]];
        // Object 1 could still be hidden at every probed rectangle.
        assert!(!probe_can_stop(&seen, all, rest.iter().copied()));
        // Unless it is known visible now.
        let not_1 = |o: u32| o != 1;
        assert!(probe_can_stop(&seen, not_1, rest.iter().copied()));
        // A rectangle left to probe tests object 2, which no probed one has.
        let rest2: [&[u32]; 2] = [&[0], &[3, 2]];
        assert!(!probe_can_stop(&seen, not_1, rest2.iter().copied()));
        // Unless object 2 is known visible too.
        assert!(probe_can_stop(
            &seen,
            |o| o != 1 && o != 2,
            rest2.iter().copied()
        ));
        // Nothing left to probe: only the tested objects count.
        assert!(probe_can_stop(&seen, not_1, std::iter::empty()));
    }

    /// [`faces_in_turn`].
    #[test]
    fn a_probe_takes_the_faces_in_turn() {
        // Faces 0, 0, 0, 2, 2, 5: each face's rectangles keep their order.
        let face = |i: usize| [0, 0, 0, 2, 2, 5][i / 10];
        let probe = vec![0, 10, 20, 30, 40, 50];
        assert_eq!(faces_in_turn(probe, face), vec![0, 30, 50, 10, 40, 20]);
        assert_eq!(faces_in_turn(vec![], face), Vec::<usize>::new());
        assert_eq!(faces_in_turn(vec![3, 7], |_| 4), vec![3, 7]);
    }

    /// [`probe_stride`]: every 16th rectangle, at least 8 and about 64 at most.
    #[test]
    fn a_probe_takes_every_16th_rectangle_within_its_bounds() {
        let probed = |n: usize| (0..n).step_by(probe_stride(n)).count();
        // Every 16th of a middling level.
        assert_eq!(probe_stride(576), 16);
        assert_eq!(probed(576), 36);
        // At least 8 of a small one, and none of a level of fewer than 16 (stride 1: the
        // whole level, no probe).
        assert_eq!(probe_stride(24), 3);
        assert_eq!(probed(24), 8);
        assert_eq!(probe_stride(15), 1);
        // About 64 of a large one, where every 16th would be hundreds.
        for n in [1_100, 4_760, 19_040, 1_000_000] {
            let p = probed(n);
            assert!((64..=66).contains(&p), "{n}: {p}");
            assert!(probe_stride(n) >= 16);
        }
    }

    /// A unit cube at finest ε = 0.25/√2 (squares of side 0.25) has 16 finest rectangles per
    /// face, whatever the levels above; a 4×2×4 cell at 0.042 about its boundary's area
    /// (64) / (2ε²) ≈ 18,000.
    #[test]
    fn finest_rectangles_count_the_full_refinement() {
        let cube = DAabb {
            min: DVec3::ZERO,
            max: DVec3::ONE,
        };
        let eps = 0.25 / std::f64::consts::SQRT_2;
        for levels in 0..4 {
            assert_eq!(
                finest_rectangles(&cube, eps, levels),
                6 * 16,
                "levels {levels}"
            );
        }
        let cell = DAabb {
            min: DVec3::ZERO,
            max: DVec3::new(4.0, 2.0, 4.0),
        };
        let n = finest_rectangles(&cell, 0.042, 2) as f64;
        let area = 2.0 * (4.0 * 2.0 + 2.0 * 4.0 + 4.0 * 4.0);
        let estimate = area / (2.0 * 0.042 * 0.042);
        assert!(
            n >= estimate && n < 2.0 * estimate,
            "{n} rectangles, about {estimate} expected"
        );
    }
}
