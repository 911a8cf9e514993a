//! The GPU section of a `render` call. [`plan_waves`] splits the planes that need the GPU into
//! *waves* (submissions) bounded in memory; [`GpuBackend::render_wave`] runs one wave in named
//! steps:
//!
//! 1. layout ([`WaveLayout::new`]): every plane's place in the shared buffers and the pools
//!    (one [`PlaneLayout`] per plane) — arithmetic only;
//! 2. allocate ([`GpuBackend::allocate`]): grow the shared buffers, add pooled targets and
//!    tables;
//! 3. upload ([`GpuBackend::upload`]): geometry, records and edges, windows, uniforms, tables;
//! 4. encode ([`GpuBackend::encode`]): with [`GpuProjection::Counting`], one compute pass
//!    for the views of every counted occluder of the wave; then per plane one render pass and
//!    one copy into its read-back buffer — or, for a plane whose occludee tests the device
//!    answers, no copy: one compute pass for all such planes builds their pyramids and answers
//!    their queries ([`super::hdm`]) — in one command buffer;
//! 5. submit ([`GpuBackend::submit`]) and map every read-back buffer;
//! 6. wait ([`GpuBackend::wait`]), polling with a timeout;
//! 7. read back ([`read_back`]): the Depth Maps, with the slice masks merged, and the answers;
//!    a kept plane's answers with its summary ([`read_kept`]).
//!
//! A plane whose map the caller asks to keep ([`RasterBackend::render_kept`]) is a tested
//! plane whose map also becomes a reprojection table on the device ([`super::hdm`]'s kept
//! planes): its table goes into a texture of the table cache, registered for a stand-in of
//! the map, and only its summary comes back.
//!
//! [`RasterBackend::render_kept`]: crate::backend::RasterBackend::render_kept

#[cfg(doc)]
use super::GpuProjection;
use super::device::{DeviceLimits, ErrorScopes};
use super::hdm::{self, KeptPlane, TestBuffers, TestedPlane};
use super::prepare::{Prepared, TableSource, merge_mask};
use super::setup::Vertex;
use super::tables::{Cached, SweepTable};
use super::{GpuBackend, RenderStats, UNIFORM_STRIDE};
use crate::backend::BackendError;
use crate::plane::{Coverage, DepthMap, KeptMap, PlaneJob, PlaneQueries, PlaneResult};
use std::collections::HashMap;
use std::num::NonZeroU64;
use std::sync::Arc;
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// Bytes of render targets + staging buffers one submission may use.
const TARGET_BUDGET: u64 = 256 << 20;
/// Bytes of vertex + record/edge data one submission may use (also capped by the device).
const DATA_BUDGET: u64 = 512 << 20;
/// Bytes of occludee queries, of depth pyramids and of slice masks one submission may use
/// (each also capped by the device's largest storage binding); planes beyond it send their
/// maps back instead.
const TEST_BUDGET: u64 = 64 << 20;
/// A wait polls back to back (yielding the thread) for this long, then pauses between polls.
const POLL_SPIN: Duration = Duration::from_micros(50);
/// Shortest and longest pause between two polls of one wait; in between, an eighth of the time
/// waited so far, so that a pause adds at most about an eighth to a long wait.
const POLL_PAUSE: (Duration, Duration) = (Duration::from_micros(20), Duration::from_millis(1));
/// Between two non-blocking polls of a wait that has lasted `waited`: a yield for the first
/// [`POLL_SPIN`], then a sleep of an eighth of `waited` within [`POLL_PAUSE`].
fn pause(waited: Duration) {
    if waited < POLL_SPIN {
        std::thread::yield_now();
    } else {
        std::thread::sleep((waited / 8).clamp(POLL_PAUSE.0, POLL_PAUSE.1));
    }
}
/// How long one blocking poll of the serial way (`GpuBackend::set_serial_polls`) blocks before
/// the device-lost flag and the deadline are checked again, and other threads may submit.
const SERIAL_POLL_SLICE: Duration = Duration::from_millis(2);
/// A submission not finished after this long is reported as a device failure.
const DEADLINE: Duration = Duration::from_secs(600);
/// Bytes of one vertex.
const VERTEX_SIZE: u64 = std::mem::size_of::<Vertex>() as u64;

/// GPU resources reused across calls.
#[derive(Default)]
pub(super) struct Pool {
    vertices: Option<wgpu::Buffer>,
    data: Option<wgpu::Buffer>,
    uniforms: Option<wgpu::Buffer>,
    /// Reprojection windows of every reprojection of a submission.
    windows: Option<wgpu::Buffer>,
    /// The counted occluders' buffers ([`GpuProjection::Counting`]), absent until a wave has
    /// some.
    views: Option<ViewBuffers>,
    /// Per map size `(width, height)`.
    targets: HashMap<(u32, u32), Vec<Target>>,
    /// Timestamp query sets, each for [`TIMESTAMPS_PER_SET`] / 2 render passes of a
    /// submission (with timestamps only).
    timestamps: Vec<TimestampSet>,
    /// The occludee tests' buffers, absent until a wave has tested planes.
    tests: Option<TestBuffers>,
}

/// The buffers of the views pass and the counted draws (`shaders/views.wgsl`).
#[derive(Default)]
struct ViewBuffers {
    points: Option<wgpu::Buffer>,
    occ: Option<wgpu::Buffer>,
    planes_f: Option<wgpu::Buffer>,
    planes_u: Option<wgpu::Buffer>,
    records: Option<wgpu::Buffer>,
}

/// `f64`s per plane in the views pass's frame buffer (`planes_f` in `shaders/views.wgsl`).
const PLANE_F64S: usize = 32;
/// Invocations per workgroup of the views pass.
const VIEWS_WORKGROUP: u32 = 64;

/// One plane's render target and its read-back buffer.
struct Target {
    view: wgpu::TextureView,
    texture: wgpu::Texture,
    staging: wgpu::Buffer,
    padded_row: u32,
}

/// A pooled resource: its size `(width, height)` and its index in the pool's list for that
/// size.
type Slot = ((u32, u32), usize);

/// A wave's reprojection tables, per plane: those its reprojections read, and the one its
/// kept map fills.
type WaveTables = (Vec<Vec<Arc<SweepTable>>>, Vec<Option<SweepTable>>);

/// Binding 0 of the occluder draws' bind groups: the plane's uniforms.
fn uniforms_entry<'a>(buffers: &WaveBuffers<'a>, plane: &PlaneLayout) -> wgpu::BindGroupEntry<'a> {
    wgpu::BindGroupEntry {
        binding: 0,
        resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
            buffer: buffers.uniforms,
            offset: plane.uniform_offset,
            size: NonZeroU64::new(16),
        }),
    }
}

/// Bytes of the views pass's points buffer: the wave's points, at least one (bound whole
/// even when every counted occluder's points are resident).
fn view_points_bytes(layout: &WaveLayout) -> u64 {
    (layout.counted_f64s as u64 * 8).max(32)
}

/// The bit of a counted occluder's count word (`RESIDENT_POINTS` in `shaders/views.wgsl`)
/// saying that its first point indexes the resident parts' points, not the wave's.
pub(super) const RESIDENT_POINTS: u32 = 0x80;
// Above every point count (`n & 0x7f` in the shader) and below the plane index (`<< 8`).
const _: () = assert!(
    RESIDENT_POINTS > 0x7f && RESIDENT_POINTS < 0x100 && super::prepare::COUNTED_MAX_POINTS <= 0x7f
);

/// Uploads the views pass's inputs: every plane's counted points, its occluders rebased onto
/// the wave's buffers (first point, `count | plane << 8`, Depth, first record word), and every
/// plane's frame (corners, rectangle, pixel scale, position and side in `f64`; axis and size in
/// `u32`). An occluder the resident parts hold (`layout.parts`) sends no points: its first
/// point is its place in that table and its count carries [`RESIDENT_POINTS`]; a part named
/// for the first time goes up to the table from the naming occluder's points (the part's,
/// bit for bit: [`crate::plane::OccluderSet::parts`]). Returns the bytes of those parts.
fn upload_views(
    queue: &wgpu::Queue,
    v: &ViewBuffers,
    layout: &WaveLayout,
    jobs: &[PlaneJob],
    prepared: &[Prepared],
) -> u64 {
    let (Some(points), Some(occ), Some(planes_f), Some(planes_u)) =
        (&v.points, &v.occ, &v.planes_f, &v.planes_u)
    else {
        unreachable!("the views buffers were just ensured");
    };
    let mut pts: Vec<f64> = Vec::with_capacity(layout.counted_f64s);
    let mut recs: Vec<[u32; 4]> = Vec::with_capacity(layout.counted);
    let mut pf: Vec<f64> = Vec::with_capacity(layout.planes.len() * PLANE_F64S);
    let mut pu: Vec<[u32; 4]> = Vec::with_capacity(layout.planes.len());
    // The named parts: their first point in the table and their points.
    let mut named: Vec<(u32, &[f64])> = Vec::new();
    let mut words = 0u32;
    for (w, plane) in layout.planes.iter().enumerate() {
        let c = &prepared[plane.job].counted;
        let table = jobs[plane.job].occluders.table;
        for (i, &[first, n, depth, rec]) in c.occ.iter().enumerate() {
            let (at, flag) = match c.resident_span(layout.parts.as_ref(), table, i) {
                Some((a, _)) => {
                    let f = 3 * first as usize;
                    let own = &c.points[f..f + 3 * n as usize];
                    debug_assert!(
                        layout
                            .parts
                            .as_ref()
                            .is_some_and(|r| (0..n as usize).all(|k| r
                                .points
                                .element(a as usize + k)
                                .is_none_or(|e| e
                                    .iter()
                                    .zip(&own[3 * k..])
                                    .all(|(x, y)| x.to_bits() == y.to_bits())))),
                        "a counted occluder names part points from {a} that are not its own"
                    );
                    named.push((a, own));
                    (a, RESIDENT_POINTS)
                }
                None => {
                    let at = (pts.len() / 3) as u32;
                    let f = 3 * first as usize;
                    pts.extend_from_slice(&c.points[f..f + 3 * n as usize]);
                    (at, 0)
                }
            };
            recs.push([at, n | flag | (w as u32) << 8, depth, rec + words]);
        }
        words += c.record_words as u32;
        let f = &jobs[plane.job].frame;
        let start = pf.len();
        for corner in f.cell.corners() {
            pf.extend(corner.to_array());
        }
        let inv = glam::DVec2::ONE / f.pixel_size();
        pf.extend([
            f.rect_min.x,
            f.rect_min.y,
            inv.x,
            inv.y,
            f.position,
            f.sign(),
        ]);
        pf.resize(start + PLANE_F64S, 0.0);
        pu.push([f.axis as u32, f.width, f.height, 0]);
    }
    debug_assert_eq!(pts.len(), layout.counted_f64s);
    // The parts first, under their table's lock: a submission after this reads them.
    let sent = layout
        .parts
        .as_ref()
        .map_or(0, |r| r.points.send_given(queue, named));
    queue.write_buffer(points, 0, bytemuck::cast_slice(&pts));
    queue.write_buffer(occ, 0, bytemuck::cast_slice(&recs));
    queue.write_buffer(planes_f, 0, bytemuck::cast_slice(&pf));
    queue.write_buffer(planes_u, 0, bytemuck::cast_slice(&pu));
    sent
}

/// Splits the planes that need the GPU (`gpu_jobs`, indexes of `jobs` and `prepared`) into
/// waves, in order, each within [`TARGET_BUDGET`] of targets, read-back buffers and tables and
/// within [`DATA_BUDGET`] (or the device's largest buffer) of uploaded data; a plane larger
/// than a budget gets a wave of its own.
pub(super) fn plan_waves(
    jobs: &[PlaneJob],
    prepared: &[Prepared],
    gpu_jobs: &[usize],
    limits: &DeviceLimits,
) -> Vec<Vec<usize>> {
    let data_budget = DATA_BUDGET.min(limits.max_buffer);
    let mut waves: Vec<Vec<usize>> = Vec::new();
    let (mut tgt, mut data, mut words) = (0u64, 0u64, 0usize);
    for &j in gpu_jobs {
        let (w, h) = (jobs[j].frame.width as u64, jobs[j].frame.height as u64);
        let p = &prepared[j];
        // Target and read-back, plus every reprojection's table (4 bytes a pixel).
        let tables: u64 = p
            .sweeps
            .iter()
            .filter(|sw| matches!(sw.table, TableSource::Upload { .. }))
            .map(|sw| sw.source_size.0 as u64 * sw.source_size.1 as u64 * 4)
            .sum();
        let t = w * h * 4 + (w * 4).next_multiple_of(256) * h + tables;
        let windows: u64 = p
            .sweeps
            .iter()
            .map(|sw| (sw.words.len() as u64 * 8).next_multiple_of(limits.storage_align))
            .sum();
        let c = &p.counted;
        let d = p.out.vertices.len() as u64 * VERTEX_SIZE
            + p.out.data.len() as u64 * 16
            + p.chunks.len() as u64 * limits.storage_align
            + windows
            + (c.points.len() * 8 + c.occ.len() * 16 + c.record_words * 16) as u64;
        // The wave's counted records are one storage binding.
        let w_words = c.record_words;
        match waves.last_mut() {
            Some(w)
                if tgt + t <= TARGET_BUDGET
                    && data + d <= data_budget
                    && words + w_words <= limits.max_chunk_words =>
            {
                w.push(j);
                tgt += t;
                data += d;
                words += w_words;
            }
            _ => {
                waves.push(vec![j]);
                tgt = t;
                data = d;
                words = w_words;
            }
        }
    }
    waves
}

/// Where one plane of a wave lies in the wave's shared buffers and in the pools.
struct PlaneLayout {
    /// Its job: the index in `jobs` and `prepared`.
    job: usize,
    /// Its first vertex in the vertex buffer.
    first_vertex: u32,
    /// Byte offset of each draw chunk's data in the data buffer.
    chunk_offsets: Vec<u64>,
    /// Byte offset of each reprojection's windows in the windows buffer.
    window_offsets: Vec<u64>,
    /// Byte offset of its uniforms in the uniform buffer.
    uniform_offset: u64,
    /// Its render target and read-back buffer.
    target: Slot,
    /// Its counted occluders: the first in the wave's occluder buffer and how many.
    counted: (u32, u32),
    /// Where its occludee tests lie, when the device answers them (its map stays there).
    tested: Option<TestedPlane>,
    /// Where its table lies, when its map is kept (it is then tested too).
    kept: Option<KeptPlane>,
}

/// A wave's layout: its planes, in order, and the bytes each shared buffer must hold.
struct WaveLayout {
    planes: Vec<PlaneLayout>,
    vertex_bytes: u64,
    data_bytes: u64,
    window_bytes: u64,
    uniform_bytes: u64,
    /// Counted occluders of the wave, their points' `f64`s and their record words.
    counted: usize,
    counted_f64s: usize,
    counted_words: usize,
    /// Of the counted occluders, those whose points the resident parts hold.
    counted_resident: usize,
    /// Tested planes of the wave, their queries, their pyramids' `f32`s, the words of their
    /// slice masks, and per reduction level `k ≥ 1` (all planes in one dispatch) the largest
    /// size of that level.
    tested: u32,
    queries: u32,
    /// Rectangle tests of the wave (its first query slots) and box tests (then
    /// [`hdm::BOX_SLOTS`] query slots each); `queries` counts the slots.
    rects: u32,
    boxes: u32,
    /// Of the box tests, those whose box goes up with the wave (the others name it in
    /// `resident`).
    inline_boxes: u32,
    /// The bake's occludee boxes on the device, when some query names them.
    resident: Option<hdm::ResidentBoxes>,
    /// The bake's occluder parts on the device, when some counted occluder is one of them.
    parts: Option<super::resident::ResidentParts>,
    pyramid_floats: u64,
    mask_words: u32,
    reduce: Vec<(u32, u32)>,
    /// Kept planes of the wave, the words of their tables, and their largest width and
    /// height.
    kept: u32,
    table_words: u64,
    kept_max: (u32, u32),
}

impl WaveLayout {
    /// Places the planes `todo` (indexes of `jobs` and `prepared`) one after the other: their
    /// vertices, their chunks' data and their reprojections' windows (each range aligned to
    /// `storage_align`), their uniforms [`UNIFORM_STRIDE`] apart, and the `k`-th plane of a
    /// size (the `k`-th table of a source size) in the pool's `k`-th target (table) of that
    /// size.
    fn new(
        todo: &[usize],
        jobs: &[PlaneJob],
        prepared: &[Prepared],
        queries: &[Option<PlaneQueries>],
        keep: &[bool],
        limits: &DeviceLimits,
        (boxes_ok, resident, parts): (
            bool,
            Option<hdm::ResidentBoxes>,
            Option<super::resident::ResidentParts>,
        ),
    ) -> Self {
        let generation = resident.as_ref().map(|r| (r.generation, r.len()));
        // A plane's boxes that go up with the wave: those its queries do not name in the
        // resident table.
        let inline = |q: &PlaneQueries| {
            (0..q.boxes.len())
                .filter(|&k| q.resident_id(generation, k).is_none())
                .count() as u64
        };
        let storage_align = limits.storage_align;
        // The tests' largest buffers (queries, pyramids) are each one storage binding.
        let test_cap = TEST_BUDGET.min(limits.max_chunk_words as u64 * 16);
        let (mut vertex_bytes, mut data_bytes, mut window_bytes) = (0u64, 0u64, 0u64);
        let mut targets_taken: HashMap<(u32, u32), usize> = HashMap::new();
        let take = |taken: &mut HashMap<(u32, u32), usize>, size: (u32, u32)| {
            let k = taken.entry(size).or_default();
            *k += 1;
            (size, *k - 1)
        };
        let mut planes = Vec::with_capacity(todo.len());
        let (mut counted, mut counted_f64s, mut counted_words) = (0usize, 0usize, 0usize);
        let (mut counted_resident, mut resident_f64s) = (0usize, 0usize);
        let (mut tested, mut n_queries, mut pyramid_floats) = (0u32, 0u32, 0u64);
        let (mut n_boxes, mut n_rects, mut n_inline) = (0u32, 0u32, 0u32);
        // Per reduction level k ≥ 1, the largest level-k size over the tested planes.
        let mut reduce: Vec<(u32, u32)> = Vec::new();
        let mut mask_words = 0u32;
        let (mut kept, mut table_words, mut kept_max) = (0u32, 0u64, (0u32, 0u32));
        for (w, &j) in todo.iter().enumerate() {
            let p = &prepared[j];
            let c = (counted as u32, p.counted.len() as u32);
            counted += p.counted.len();
            // The occluders whose points the resident parts hold.
            let table = jobs[j].occluders.table;
            counted_f64s += p.counted.points.len();
            for (a, b) in (0..p.counted.len())
                .filter_map(|i| p.counted.resident_span(parts.as_ref(), table, i))
            {
                counted_resident += 1;
                resident_f64s += 3 * (b - a) as usize;
            }
            counted_words += p.counted.record_words;
            let first_vertex = (vertex_bytes / VERTEX_SIZE) as u32;
            vertex_bytes += p.out.vertices.len() as u64 * VERTEX_SIZE;
            let mut chunk_offsets = Vec::with_capacity(p.chunks.len());
            for c in &p.chunks {
                chunk_offsets.push(data_bytes);
                data_bytes += ((c.data.len() as u64) * 16).next_multiple_of(storage_align);
            }
            let mut window_offsets = Vec::with_capacity(p.sweeps.len());
            for sw in &p.sweeps {
                window_offsets.push(window_bytes);
                window_bytes += (sw.words.len() as u64 * 8).next_multiple_of(storage_align);
            }
            let f = &jobs[j].frame;
            // The device answers a plane's queries when asked (its slices' mask goes up as
            // bits and is merged there), and keeps its map when asked and its table fits.
            let table = u64::from(hdm::table_stride(f.width)) * u64::from(f.height);
            let q_inline = queries[j].as_ref().map_or(0, inline);
            let slots = |q: &PlaneQueries| {
                q.rects.len() as u64 + q.boxes.len() as u64 * u64::from(hdm::BOX_SLOTS)
            };
            let fits = |q: &PlaneQueries| {
                let mask = p
                    .mask
                    .as_ref()
                    .map_or(0, |m| m.depth.len().div_ceil(32) as u64);
                (q.boxes.is_empty() || boxes_ok)
                    && (u64::from(n_queries) + slots(q)) * hdm::QUERY_BYTES <= test_cap
                    && (u64::from(n_inline) + q_inline) * hdm::BOX_BYTES <= test_cap
                    && (u64::from(n_boxes) + q.boxes.len() as u64) * 8 <= test_cap
                    && (pyramid_floats + hdm::pyramid_floats(f.width, f.height)) * 4 <= test_cap
                    && (u64::from(mask_words) + mask) * 4 <= test_cap
                    && f.width.max(f.height) <= hdm::MAX_SIDE
                    && (!keep[j] || (table_words + table) * 4 <= test_cap)
            };
            let t = match &queries[j] {
                Some(q) if fits(q) => {
                    let mask = p.mask.as_ref().map(|m| {
                        let at = mask_words;
                        mask_words += m.depth.len().div_ceil(32) as u32;
                        at
                    });
                    let levels = hdm::level_params(f.width, f.height, pyramid_floats as u32, mask);
                    let t = TestedPlane {
                        index: tested,
                        rects: (n_rects, q.rects.len() as u32),
                        boxes: (n_boxes, q.boxes.len() as u32),
                        levels,
                        mask,
                    };
                    tested += 1;
                    n_queries += slots(q) as u32;
                    n_rects += q.rects.len() as u32;
                    n_boxes += q.boxes.len() as u32;
                    n_inline += q_inline as u32;
                    pyramid_floats += hdm::pyramid_floats(f.width, f.height);
                    for (k, l) in t.levels.iter().enumerate().skip(1) {
                        if reduce.len() < k {
                            reduce.push((0, 0));
                        }
                        let r = &mut reduce[k - 1];
                        *r = (r.0.max(l.dst_w), r.1.max(l.dst_h));
                    }
                    Some(t)
                }
                _ => None,
            };
            let k = (t.is_some() && keep[j]).then(|| {
                let k = KeptPlane {
                    index: kept,
                    table: table_words as u32,
                    stride: hdm::table_stride(f.width),
                };
                kept += 1;
                table_words += table;
                kept_max = (kept_max.0.max(f.width), kept_max.1.max(f.height));
                k
            });
            planes.push(PlaneLayout {
                job: j,
                first_vertex,
                chunk_offsets,
                window_offsets,
                uniform_offset: w as u64 * UNIFORM_STRIDE,
                target: take(&mut targets_taken, (f.width, f.height)),
                counted: c,
                tested: t,
                kept: k,
            });
        }
        WaveLayout {
            planes,
            vertex_bytes,
            data_bytes,
            window_bytes,
            uniform_bytes: todo.len() as u64 * UNIFORM_STRIDE,
            counted,
            // The points of the occluders the resident parts do not hold go up.
            counted_f64s: counted_f64s - resident_f64s,
            counted_resident,
            counted_words,
            tested,
            queries: n_queries,
            rects: n_rects,
            boxes: n_boxes,
            inline_boxes: n_inline,
            resident: resident.filter(|_| n_inline < n_boxes),
            parts: parts.filter(|_| counted_resident > 0),
            pyramid_floats,
            mask_words,
            reduce,
            kept,
            table_words,
            kept_max,
        }
    }

    /// Bytes of the box tests' words: each tested plane's first test and the total, then a
    /// word per test naming its box (`box_meta` in `shaders/boxes.wgsl`).
    fn box_meta_bytes(&self) -> u64 {
        (u64::from(self.tested) + 1 + u64::from(self.boxes)) * 4
    }

    /// Answers read back: the rectangle tests', then the box tests'.
    fn answers(&self) -> u32 {
        self.rects + self.boxes
    }

    /// The query slot of box test `k` of the wave (its first of [`hdm::BOX_SLOTS`]).
    fn box_slot(&self, k: u32) -> u32 {
        self.rects + k * hdm::BOX_SLOTS
    }

    /// Slots of the params buffer: each tested plane's `base` dispatch, then each reduction
    /// level's.
    fn params(&self) -> u32 {
        self.tested + self.reduce.len() as u32
    }

    /// The read-back mappings: one per plane whose map comes back, one per timestamp set, one
    /// for the answers when the wave has tested planes and one for the summaries when it has
    /// kept planes.
    fn mappings(&self, timestamp_sets: usize) -> usize {
        self.planes.iter().filter(|p| p.tested.is_none()).count()
            + timestamp_sets
            + usize::from(self.tested > 0)
            + usize::from(self.kept > 0)
    }

    /// Passes timed with timestamps: every plane's render pass, then the views pass when the
    /// wave has counted occluders.
    fn timed_passes(&self) -> usize {
        self.planes.len() + usize::from(self.counted > 0)
    }

    /// Bytes the views pass uploads: points, occluders, and every plane's frame.
    fn view_bytes(&self) -> u64 {
        if self.counted == 0 {
            return 0;
        }
        (self.counted_f64s * 8 + self.counted * 16 + self.planes.len() * (PLANE_F64S * 8 + 16))
            as u64
    }

    /// Adds the wave's counters to `stats`: one submission, per plane one pass, its draws,
    /// occluders, triangles and edges, and the bytes uploaded and read back.
    fn count(&self, jobs: &[PlaneJob], prepared: &[Prepared], stats: &mut RenderStats) {
        stats.submissions += 1;
        stats.passes += self.planes.len();
        stats.bytes_uploaded += self.vertex_bytes + self.uniform_bytes + self.view_bytes();
        stats.counted_resident += self.counted_resident;
        for plane in &self.planes {
            let p = &prepared[plane.job];
            for sw in &p.sweeps {
                stats.reprojections += 1;
                stats.draws += 1;
                stats.bytes_uploaded += sw.words.len() as u64 * 8;
                match &sw.table {
                    TableSource::Upload { table, .. } => {
                        stats.tables_uploaded += 1;
                        stats.bytes_uploaded += table.len() as u64 * 4;
                    }
                    TableSource::Cached(_) => stats.tables_reused += 1,
                }
            }
            stats.draws += p.chunks.len() + usize::from(!p.counted.is_empty());
            stats.counted += p.counted.len();
            stats.occluders += p.occluders;
            stats.triangles += p.out.vertices.len() / 3;
            stats.edges += p.out.data.len() - p.occluders;
            stats.bytes_uploaded += p.out.data.len() as u64 * 16;
            let f = &jobs[plane.job].frame;
            if plane.tested.is_none() {
                stats.maps_read_back += 1;
                stats.bytes_read_back +=
                    (f.width as u64 * 4).next_multiple_of(256) * f.height as u64;
            }
        }
        if self.tested > 0 {
            stats.bytes_uploaded += u64::from(self.rects) * hdm::QUERY_BYTES
                + u64::from(self.tested) * hdm::PLANE_BYTES
                + u64::from(self.params()) * UNIFORM_STRIDE
                + u64::from(self.tested) * hdm::MAX_LEVELS as u64 * hdm::LEVEL_BYTES
                + u64::from(self.mask_words) * 4
                + 16;
            stats.bytes_read_back += u64::from(self.answers()) * 4;
            if self.boxes > 0 {
                stats.bytes_uploaded += self.box_meta_bytes()
                    + u64::from(self.inline_boxes) * hdm::BOX_BYTES
                    + u64::from(self.tested) * (hdm::BOX_FRAME_F64S as u64 * 8 + 16)
                    + 16;
            }
        }
        let kept = u64::from(self.kept);
        stats.bytes_uploaded += kept * (hdm::KEPT_BYTES + hdm::SUMMARY_WORDS * 4);
        stats.bytes_read_back += kept * hdm::SUMMARY_WORDS * 4;
        stats.kept_maps += self.kept as usize;
    }
}

/// The wave's shared buffers, once allocated.
struct WaveBuffers<'a> {
    vertices: &'a wgpu::Buffer,
    data: &'a wgpu::Buffer,
    uniforms: &'a wgpu::Buffer,
    /// Absent until some wave reprojects.
    windows: Option<&'a wgpu::Buffer>,
    /// Absent until some wave has counted occluders.
    views: Option<&'a ViewBuffers>,
    /// Per plane of the wave, each reprojection's summed-area table.
    tables: Vec<Vec<Arc<SweepTable>>>,
    /// Per plane of the wave, the table texture its kept map fills.
    kept: Vec<Option<SweepTable>>,
}

impl<'a> WaveBuffers<'a> {
    /// The pool's buffers and the wave's tables, after [`GpuBackend::allocate`].
    fn of(pool: &'a Pool, (tables, kept): WaveTables) -> Self {
        let (Some(vertices), Some(data), Some(uniforms)) =
            (&pool.vertices, &pool.data, &pool.uniforms)
        else {
            unreachable!("buffers were just ensured");
        };
        WaveBuffers {
            vertices,
            data,
            uniforms,
            windows: pool.windows.as_ref(),
            views: pool.views.as_ref(),
            tables,
            kept,
        }
    }
}

impl GpuBackend {
    /// Renders one submission's worth of jobs (`todo` indexes `jobs` and `prepared`) into
    /// `out`, in the steps listed in the [module docs](self), inside error scopes.
    ///
    /// # Errors
    /// [`BackendError::BufferTooLarge`] when a buffer would exceed the device's limits;
    /// [`BackendError::Validation`] or [`BackendError::OutOfMemory`] from the error scopes;
    /// otherwise as [`Self::wait`] and [`read_back`].
    #[expect(
        clippy::too_many_arguments,
        reason = "the call's jobs, their set-up and queries, the wave, its outputs and counters"
    )]
    pub(super) fn render_wave(
        &self,
        pool: &mut Pool,
        jobs: &[PlaneJob],
        prepared: &[Prepared],
        (queries, keep): (&[Option<PlaneQueries>], &[bool]),
        todo: &[usize],
        out: &mut [Option<PlaneResult>],
        stats: &mut RenderStats,
    ) -> Result<(), BackendError> {
        let scope = ErrorScopes::push(&self.device);
        let layout = WaveLayout::new(
            todo,
            jobs,
            prepared,
            queries,
            keep,
            &self.limits,
            (
                self.box_pipelines.is_some(),
                self.resident_boxes(),
                self.resident_parts(),
            ),
        );
        let tables = self.allocate(pool, &layout, prepared)?;
        let pool = &*pool;
        let buffers = WaveBuffers::of(pool, tables);
        let parts_bytes = self.upload(&buffers, &layout, jobs, prepared);
        let resident_bytes = self.upload_tests(pool, &layout, jobs, prepared, queries);
        layout.count(jobs, prepared, stats);
        stats.bytes_uploaded += resident_bytes + parts_bytes;
        let timestamps = self.timestamp_period.map(|period| Timestamps {
            sets: &pool.timestamps[..timestamp_sets(layout.timed_passes())],
            passes: layout.timed_passes(),
            period,
        });
        let commands = self.encode(pool, &buffers, &layout, prepared, timestamps.as_ref());
        let kept_tables = buffers.kept;
        let (submission, mapped) = self.submit(pool, &layout, commands, timestamps.as_ref());
        scope.check()?;
        let waited = layout.mappings(timestamps.as_ref().map_or(0, |t| t.sets.len()));
        self.wait(&submission, mapped, waited)?;
        self.check_failure()?;
        if let Some(t) = &timestamps {
            let (all, last) = t.read()?;
            stats.pass_time += all;
            stats.timed_passes += layout.timed_passes();
            if layout.counted > 0 {
                stats.views_time += last;
            }
        }
        read_back(pool, &layout, prepared, out)?;
        read_answers(pool, &layout, out)?;
        self.read_kept(pool, &layout, jobs, kept_tables, out)
    }

    /// Allocation step: grows the shared buffers to the layout's sizes and adds to the pools
    /// the targets and tables it places beyond their ends.
    ///
    /// # Errors
    /// [`BackendError::BufferTooLarge`] when a buffer would exceed the device's largest.
    fn allocate(
        &self,
        pool: &mut Pool,
        layout: &WaveLayout,
        prepared: &[Prepared],
    ) -> Result<WaveTables, BackendError> {
        if self.timestamp_period.is_some() {
            while pool.timestamps.len() < timestamp_sets(layout.timed_passes()) {
                pool.timestamps.push(TimestampSet::new(&self.device));
            }
        }
        if layout.counted > 0 {
            let v = pool.views.get_or_insert_with(ViewBuffers::default);
            let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
            self.ensure_buffer(
                &mut v.points,
                view_points_bytes(layout),
                storage,
                "counted occluder points",
            )?;
            self.ensure_buffer(
                &mut v.occ,
                layout.counted as u64 * 16,
                storage,
                "counted occluders",
            )?;
            self.ensure_buffer(
                &mut v.planes_f,
                (layout.planes.len() * PLANE_F64S * 8) as u64,
                storage,
                "counted plane frames (f64)",
            )?;
            self.ensure_buffer(
                &mut v.planes_u,
                layout.planes.len() as u64 * 16,
                storage,
                "counted plane frames (u32)",
            )?;
            self.ensure_buffer(
                &mut v.records,
                layout.counted_words as u64 * 16,
                wgpu::BufferUsages::STORAGE,
                "counted occluder records and view edges",
            )?;
        }
        if layout.tested > 0 {
            let t = pool.tests.get_or_insert_with(TestBuffers::default);
            let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
            let q = u64::from(layout.queries).max(1);
            self.ensure_buffer(
                &mut t.pyramid,
                layout.pyramid_floats * 4,
                wgpu::BufferUsages::STORAGE,
                "depth pyramids",
            )?;
            self.ensure_buffer(
                &mut t.steps,
                u64::from(layout.tested) * hdm::MAX_LEVELS as u64 * hdm::LEVEL_BYTES,
                storage,
                "depth pyramid steps",
            )?;
            self.ensure_buffer(
                &mut t.params,
                u64::from(layout.params()) * UNIFORM_STRIDE,
                wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                "depth pyramid levels",
            )?;
            self.ensure_buffer(
                &mut t.planes,
                u64::from(layout.tested) * hdm::PLANE_BYTES,
                storage,
                "tested planes",
            )?;
            self.ensure_buffer(
                &mut t.queries,
                q * hdm::QUERY_BYTES,
                storage,
                "occludee queries",
            )?;
            self.ensure_buffer(
                &mut t.answers,
                q * 4,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                "occludee answers",
            )?;
            self.ensure_buffer(
                &mut t.masks,
                u64::from(layout.mask_words.max(1)) * 4,
                storage,
                "slice masks",
            )?;
            self.ensure_buffer(
                &mut t.count,
                16,
                wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                "occludee query count",
            )?;
            self.ensure_buffer(
                &mut t.staging,
                u64::from(layout.answers()).max(1) * 4,
                wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                "occludee answers read-back",
            )?;
        }
        if layout.boxes > 0 {
            let t = pool.tests.get_or_insert_with(TestBuffers::default);
            let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
            let n = u64::from(layout.boxes);
            let inline = u64::from(layout.inline_boxes.max(1));
            self.ensure_buffer(
                &mut t.boxes,
                inline * hdm::BOX_BYTES,
                storage,
                "occludee boxes",
            )?;
            self.ensure_buffer(
                &mut t.box_meta,
                layout.box_meta_bytes(),
                storage,
                "occludee box tests' planes and boxes",
            )?;
            self.ensure_buffer(
                &mut t.frames_f,
                u64::from(layout.tested) * hdm::BOX_FRAME_F64S as u64 * 8,
                storage,
                "box-tested plane frames (f64)",
            )?;
            self.ensure_buffer(
                &mut t.frames_u,
                u64::from(layout.tested) * 16,
                storage,
                "box-tested plane frames (u32)",
            )?;
            self.ensure_buffer(
                &mut t.shapes,
                n * 4,
                wgpu::BufferUsages::STORAGE,
                "occludee boxes' shapes",
            )?;
            self.ensure_buffer(
                &mut t.box_count,
                16,
                wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                "occludee box count",
            )?;
            self.ensure_buffer(
                &mut t.box_out,
                n * 4,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                "occludee boxes' answers",
            )?;
        }
        if layout.kept > 0 {
            let t = pool.tests.get_or_insert_with(TestBuffers::default);
            let n = u64::from(layout.kept);
            self.ensure_buffer(
                &mut t.kept,
                n * hdm::KEPT_BYTES,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                "kept planes",
            )?;
            self.ensure_buffer(
                &mut t.tables,
                layout.table_words * 4,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                "kept planes' tables",
            )?;
            self.ensure_buffer(
                &mut t.summary,
                n * hdm::SUMMARY_WORDS * 4,
                wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
                "kept planes' summaries",
            )?;
            self.ensure_buffer(
                &mut t.summary_staging,
                n * hdm::SUMMARY_WORDS * 4,
                wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                "kept planes' summaries read-back",
            )?;
        }
        if layout.window_bytes > 0 {
            self.ensure_buffer(
                &mut pool.windows,
                layout.window_bytes,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                "reprojection windows",
            )?;
        }
        self.ensure_buffer(
            &mut pool.vertices,
            layout.vertex_bytes.max(VERTEX_SIZE),
            wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
            "occluder geometry",
        )?;
        self.ensure_buffer(
            &mut pool.data,
            layout.data_bytes.max(16),
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            "occluder records and view edges",
        )?;
        self.ensure_buffer(
            &mut pool.uniforms,
            layout.uniform_bytes,
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            "plane uniforms",
        )?;
        let mut tables = Vec::with_capacity(layout.planes.len());
        let mut kept = Vec::with_capacity(layout.planes.len());
        for plane in &layout.planes {
            kept.push(plane.kept.as_ref().map(|_| {
                let size = plane.target.0;
                self.tables
                    .take_free(size)
                    .unwrap_or_else(|| self.new_sweep_table(size))
            }));
            let (size, k) = plane.target;
            let list = pool.targets.entry(size).or_default();
            if list.len() <= k {
                list.push(self.new_target(size));
            }
            tables.push(
                prepared[plane.job]
                    .sweeps
                    .iter()
                    .map(|sw| match &sw.table {
                        TableSource::Cached(t) => t.clone(),
                        TableSource::Upload { .. } => Arc::new(
                            self.tables
                                .take_free(sw.source_size)
                                .unwrap_or_else(|| self.new_sweep_table(sw.source_size)),
                        ),
                    })
                    .collect(),
            );
        }
        Ok((tables, kept))
    }

    /// Upload step: every plane's vertices, chunks of records and edges and reprojection
    /// windows at their offsets, the planes' uniforms (`2 / width`, `2 / height`: pixel to
    /// NDC scale), the views pass's inputs, then the reprojections' summed-area tables.
    /// Returns the bytes of resident parts sent (the rest is counted by the layout).
    fn upload(
        &self,
        buffers: &WaveBuffers,
        layout: &WaveLayout,
        jobs: &[PlaneJob],
        prepared: &[Prepared],
    ) -> u64 {
        let mut uniforms = vec![0u8; layout.uniform_bytes as usize];
        for plane in &layout.planes {
            let p = &prepared[plane.job];
            if !p.out.vertices.is_empty() {
                self.queue.write_buffer(
                    buffers.vertices,
                    plane.first_vertex as u64 * VERTEX_SIZE,
                    bytemuck::cast_slice(&p.out.vertices),
                );
            }
            for (c, &off) in p.chunks.iter().zip(&plane.chunk_offsets) {
                if !c.data.is_empty() {
                    self.queue.write_buffer(
                        buffers.data,
                        off,
                        bytemuck::cast_slice(&p.out.data[c.data.clone()]),
                    );
                }
            }
            if let Some(buf) = buffers.windows {
                for (sw, &off) in p.sweeps.iter().zip(&plane.window_offsets) {
                    self.queue
                        .write_buffer(buf, off, bytemuck::cast_slice(sw.words.as_slice()));
                }
            }
            let f = &jobs[plane.job].frame;
            let o = plane.uniform_offset as usize;
            uniforms[o..o + 4].copy_from_slice(&(2.0f32 / f.width as f32).to_le_bytes());
            uniforms[o + 4..o + 8].copy_from_slice(&(2.0f32 / f.height as f32).to_le_bytes());
        }
        self.queue.write_buffer(buffers.uniforms, 0, &uniforms);
        let mut sent = 0;
        if let (Some(v), true) = (buffers.views, layout.counted > 0) {
            sent = upload_views(&self.queue, v, layout, jobs, prepared);
        }
        for (plane, tables) in layout.planes.iter().zip(&buffers.tables) {
            for (sw, t) in prepared[plane.job].sweeps.iter().zip(tables) {
                let TableSource::Upload {
                    table,
                    source,
                    umbra,
                } = &sw.table
                else {
                    continue;
                };
                let (width, height) = sw.source_size;
                self.queue.write_texture(
                    wgpu::TexelCopyTextureInfo {
                        texture: &t.texture,
                        mip_level: 0,
                        origin: wgpu::Origin3d::ZERO,
                        aspect: wgpu::TextureAspect::All,
                    },
                    bytemuck::cast_slice(table),
                    wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some(width * 4),
                        rows_per_image: Some(height),
                    },
                    wgpu::Extent3d {
                        width,
                        height,
                        depth_or_array_layers: 1,
                    },
                );
                // Later reprojections of this source (this call's or later ones') use it.
                self.tables.insert(
                    source,
                    Cached {
                        table: Some(t.clone()),
                        umbra: Some(*umbra),
                    },
                );
            }
        }
        sent
    }

    /// Upload step of the occludee tests: each dispatch's level parameters, the tested planes,
    /// their queries (`plane, i0 | j0 << 16, i1 | j1 << 16, depth`) and their count, the box
    /// tests (each tested plane's first test, each test's box, the boxes not resident) and the
    /// resident boxes named
    /// for the first time. Returns the bytes of those resident boxes.
    fn upload_tests(
        &self,
        pool: &Pool,
        layout: &WaveLayout,
        jobs: &[PlaneJob],
        prepared: &[Prepared],
        queries: &[Option<PlaneQueries>],
    ) -> u64 {
        let Some(t) = pool.tests.as_ref().filter(|_| layout.tested > 0) else {
            return 0;
        };
        let (Some(params), Some(planes), Some(qbuf), Some(count), Some(masks), Some(steps)) = (
            &t.params, &t.planes, &t.queries, &t.count, &t.masks, &t.steps,
        ) else {
            unreachable!("test buffers were just ensured");
        };
        let mut step_words: Vec<hdm::LevelParams> =
            vec![hdm::LevelParams::default(); layout.tested as usize * hdm::MAX_LEVELS];
        let mut mask_words: Vec<u32> = Vec::with_capacity(layout.mask_words as usize);
        let mut param_bytes = vec![0u8; (u64::from(layout.params()) * UNIFORM_STRIDE) as usize];
        let mut put = |slot: u32, lp: &hdm::LevelParams| {
            let o = hdm::param_offset(slot) as usize;
            let b = bytemuck::bytes_of(lp);
            param_bytes[o..o + b.len()].copy_from_slice(b);
        };
        for k in 1..=layout.reduce.len() as u32 {
            put(layout.tested + k - 1, &hdm::reduce_slot(k));
        }
        let mut plane_words: Vec<u32> = Vec::with_capacity(layout.tested as usize * 4);
        let mut query_words: Vec<u32> = Vec::with_capacity(layout.rects as usize * 4);
        let mut box_f64s: Vec<f64> = Vec::with_capacity(layout.inline_boxes as usize * 6);
        let generation = layout.resident.as_ref().map(|r| (r.generation, r.len()));
        // The resident boxes named, with their values (the first naming sends them).
        let mut named: Vec<(u32, [f64; 6])> = Vec::new();
        // Each tested plane's first box test, then each test's box (`box_meta` in
        // `shaders/boxes.wgsl`).
        let mut box_starts: Vec<u32> = Vec::with_capacity(layout.tested as usize + 1);
        let mut box_words: Vec<u32> = Vec::with_capacity(layout.boxes as usize);
        let mut frame_f64s: Vec<f64> = Vec::new();
        let mut frame_words: Vec<u32> = Vec::new();
        for plane in &layout.planes {
            let Some(tp) = &plane.tested else { continue };
            put(tp.index, &tp.levels[0]);
            let first = tp.index as usize * hdm::MAX_LEVELS;
            step_words[first..first + tp.levels.len()].copy_from_slice(&tp.levels);
            plane_words.extend_from_slice(&hdm::plane_words(tp));
            if let Some(m) = &prepared[plane.job].mask {
                debug_assert_eq!(tp.mask, Some(mask_words.len() as u32));
                mask_words.extend(hdm::mask_bits(m));
            }
            let q = queries[plane.job]
                .as_ref()
                .expect("a tested plane has queries");
            for q in &q.rects {
                let [i0, j0, i1, j1] = q.rect;
                query_words.extend_from_slice(&[
                    tp.index,
                    i0 | j0 << 16,
                    i1 | j1 << 16,
                    q.depth.to_bits(),
                ]);
            }
            // (The box tests' slots, after every rectangle test, are filled on the device by
            // `box_plan`.)
            if layout.boxes > 0 {
                debug_assert_eq!(
                    tp.index as usize,
                    box_starts.len(),
                    "tested planes in order"
                );
                box_starts.push(box_words.len() as u32);
                let (ff, fu) = hdm::box_frame(&jobs[plane.job].frame, q.improved);
                frame_f64s.extend_from_slice(&ff);
                frame_words.extend_from_slice(&fu);
                // (Each test's query slots follow from its place: `box_slot`.)
                for (k, b) in q.boxes.iter().enumerate() {
                    let values = hdm::box_f64s(b);
                    let src = match q.resident_id(generation, k) {
                        Some(id) => {
                            debug_assert!(
                                layout.resident.as_ref().is_some_and(|r| r
                                    .element(id as usize)
                                    .is_none_or(|e| e == values)),
                                "a query names box {id} of the resident table for another box"
                            );
                            named.push((id, values));
                            id
                        }
                        None => {
                            let at = (box_f64s.len() / 6) as u32;
                            box_f64s.extend_from_slice(&values);
                            hdm::INLINE_BOX | at
                        }
                    };
                    box_words.push(src);
                }
            }
        }
        if layout.boxes > 0 {
            let (Some(bx), Some(meta), Some(ff), Some(fu), Some(bc)) = (
                &t.boxes,
                &t.box_meta,
                &t.frames_f,
                &t.frames_u,
                &t.box_count,
            ) else {
                unreachable!("box buffers were just ensured");
            };
            if !box_f64s.is_empty() {
                self.queue
                    .write_buffer(bx, 0, bytemuck::cast_slice(&box_f64s));
            }
            debug_assert_eq!(box_starts.len(), layout.tested as usize);
            box_starts.push(box_words.len() as u32);
            box_starts.extend_from_slice(&box_words);
            self.queue
                .write_buffer(meta, 0, bytemuck::cast_slice(&box_starts));
            self.queue
                .write_buffer(ff, 0, bytemuck::cast_slice(&frame_f64s));
            self.queue
                .write_buffer(fu, 0, bytemuck::cast_slice(&frame_words));
            self.queue.write_buffer(
                bc,
                0,
                bytemuck::cast_slice(&[layout.boxes, layout.box_slot(0), layout.tested, 0]),
            );
        }
        self.queue.write_buffer(params, 0, &param_bytes);
        self.queue
            .write_buffer(steps, 0, bytemuck::cast_slice(&step_words));
        if !mask_words.is_empty() {
            self.queue
                .write_buffer(masks, 0, bytemuck::cast_slice(&mask_words));
        }
        self.queue
            .write_buffer(planes, 0, bytemuck::cast_slice(&plane_words));
        if !query_words.is_empty() {
            self.queue
                .write_buffer(qbuf, 0, bytemuck::cast_slice(&query_words));
        }
        self.queue
            .write_buffer(count, 0, bytemuck::cast_slice(&[layout.queries, 0, 0, 0]));
        if layout.kept > 0 {
            let (Some(kept), Some(summary)) = (&t.kept, &t.summary) else {
                unreachable!("kept planes' buffers were just ensured");
            };
            let mut kept_words: Vec<u32> = Vec::with_capacity(layout.kept as usize * 8);
            for plane in &layout.planes {
                if let (Some(tp), Some(kp)) = (&plane.tested, &plane.kept) {
                    debug_assert_eq!(kept_words.len(), kp.index as usize * 8);
                    kept_words.extend_from_slice(&hdm::kept_words(tp, kp));
                }
            }
            self.queue
                .write_buffer(kept, 0, bytemuck::cast_slice(&kept_words));
            let start: Vec<u32> = (0..layout.kept).flat_map(|_| hdm::SUMMARY_START).collect();
            self.queue
                .write_buffer(summary, 0, bytemuck::cast_slice(&start));
        }
        // The resident boxes this wave names that no earlier wave sent.
        layout.resident.as_ref().map_or(0, |r| {
            let runs = named.iter().map(|(id, b)| (*id, &b[..])).collect();
            r.send_given(&self.queue, runs)
        })
    }

    /// The occludee tests of the wave's tested planes, after their render passes: one compute
    /// pass copies each target into the pyramid buffer and reduces it level by level, then
    /// answers every query; the answers are copied into their read-back buffer.
    fn encode_tests(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        pool: &Pool,
        buffers: &WaveBuffers,
        layout: &WaveLayout,
    ) {
        let Some(t) = pool.tests.as_ref().filter(|_| layout.tested > 0) else {
            return;
        };
        let (Some(pyramid), Some(params), Some(planes), Some(queries), Some(answers)) =
            (&t.pyramid, &t.params, &t.planes, &t.queries, &t.answers)
        else {
            unreachable!("test buffers were just ensured");
        };
        let (Some(count), Some(staging), Some(masks), Some(steps)) =
            (&t.count, &t.staging, &t.masks, &t.steps)
        else {
            unreachable!("test buffers were just ensured");
        };
        let p = &self.hdm_pipelines;
        // Each binding just the wave's part: the buffers grow in powers of two, past what a
        // device's largest binding may be.
        fn part(buffer: &wgpu::Buffer, bytes: u64) -> wgpu::BindingResource<'_> {
            wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer,
                offset: 0,
                size: NonZeroU64::new(bytes.max(16)),
            })
        }
        let q = u64::from(layout.queries);
        let level_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("hdm level bind group"),
            layout: &p.level_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: params,
                        offset: 0,
                        size: NonZeroU64::new(std::mem::size_of::<hdm::LevelParams>() as u64),
                    }),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: part(pyramid, layout.pyramid_floats * 4),
                },
                wgpu::BindGroupEntry {
                    binding: 7,
                    resource: part(masks, u64::from(layout.mask_words) * 4),
                },
                wgpu::BindGroupEntry {
                    binding: 8,
                    resource: part(
                        steps,
                        u64::from(layout.tested) * hdm::MAX_LEVELS as u64 * hdm::LEVEL_BYTES,
                    ),
                },
            ],
        });
        let answer_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("hdm answer bind group"),
            layout: &p.answer_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: part(pyramid, layout.pyramid_floats * 4),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: part(planes, u64::from(layout.tested) * hdm::PLANE_BYTES),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: part(queries, q * hdm::QUERY_BYTES),
                },
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: part(answers, q * 4),
                },
                wgpu::BindGroupEntry {
                    binding: 6,
                    resource: part(count, 16),
                },
            ],
        });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("occludee tests"),
                timestamp_writes: None,
            });
            for plane in &layout.planes {
                let Some(tp) = &plane.tested else { continue };
                let (size, k) = plane.target;
                let map_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("hdm map bind group"),
                    layout: &p.map_layout,
                    entries: &[wgpu::BindGroupEntry {
                        binding: 0,
                        resource: wgpu::BindingResource::TextureView(&pool.targets[&size][k].view),
                    }],
                });
                let base = &tp.levels[0];
                pass.set_pipeline(&p.base);
                pass.set_bind_group(1, &map_group, &[]);
                pass.set_bind_group(0, &level_group, &[hdm::param_offset(tp.index) as u32]);
                let (x, y) = hdm::level_groups((base.dst_w, base.dst_h));
                pass.dispatch_workgroups(x, y, 1);
            }
            // Each coarser level of every plane in one dispatch (plane = z).
            pass.set_pipeline(&p.reduce);
            for (k, &size) in layout.reduce.iter().enumerate() {
                let slot = layout.tested + k as u32;
                pass.set_bind_group(0, &level_group, &[hdm::param_offset(slot) as u32]);
                let (x, y) = hdm::level_groups(size);
                pass.dispatch_workgroups(x, y, layout.tested);
            }
            let box_group = (layout.boxes > 0).then(|| self.box_bind_group(t, layout));
            if let (Some(g), Some(bp)) = (&box_group, &self.box_pipelines) {
                pass.set_pipeline(&bp.plan);
                pass.set_bind_group(0, g, &[]);
                pass.dispatch_workgroups(hdm::box_groups(layout.boxes), 1, 1);
            }
            if layout.queries > 0 {
                pass.set_pipeline(&p.answer);
                pass.set_bind_group(0, &answer_group, &[]);
                pass.dispatch_workgroups(hdm::answer_groups(layout.queries), 1, 1);
            }
            if let (Some(g), Some(bp)) = (&box_group, &self.box_pipelines) {
                pass.set_pipeline(&bp.decide);
                pass.set_bind_group(0, g, &[]);
                pass.dispatch_workgroups(hdm::box_groups(layout.boxes), 1, 1);
            }
            if layout.kept > 0 {
                let sat_group = self.sat_bind_group(t, layout);
                pass.set_bind_group(0, &sat_group, &[]);
                pass.set_pipeline(&p.sat_rows);
                pass.dispatch_workgroups(hdm::sat_groups(layout.kept_max.1), 1, layout.kept);
                pass.set_pipeline(&p.sat_cols);
                pass.dispatch_workgroups(hdm::sat_groups(layout.kept_max.0), 1, layout.kept);
            }
        }
        if layout.rects > 0 {
            encoder.copy_buffer_to_buffer(answers, 0, staging, 0, u64::from(layout.rects) * 4);
        }
        if let Some(box_out) = t.box_out.as_ref().filter(|_| layout.boxes > 0) {
            let at = u64::from(layout.rects) * 4;
            encoder.copy_buffer_to_buffer(box_out, 0, staging, at, u64::from(layout.boxes) * 4);
        }
        if layout.kept > 0 {
            self.encode_kept_copies(encoder, t, buffers, layout);
        }
    }

    /// The bind group of the box tests' passes (`box_plan`, `box_decide`).
    fn box_bind_group(&self, t: &TestBuffers, layout: &WaveLayout) -> wgpu::BindGroup {
        let (Some(bx), Some(meta), Some(ff), Some(fu), Some(shapes), Some(bc), Some(box_out)) = (
            &t.boxes,
            &t.box_meta,
            &t.frames_f,
            &t.frames_u,
            &t.shapes,
            &t.box_count,
            &t.box_out,
        ) else {
            unreachable!("box buffers were just ensured");
        };
        let (Some(queries), Some(answers)) = (&t.queries, &t.answers) else {
            unreachable!("test buffers were just ensured");
        };
        let bp = self
            .box_pipelines
            .as_ref()
            .expect("box tests are laid out only with their pipelines");
        let n = u64::from(layout.boxes);
        let q = u64::from(layout.queries);
        let (resident, resident_bytes) = match &layout.resident {
            Some(r) => (&*r.buffer, r.bytes()),
            None => (&bp.no_resident, hdm::BOX_BYTES),
        };
        let entry = buffer_entry;
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("box tests bind group"),
            layout: &bp.layout,
            entries: &[
                entry(
                    0,
                    bx,
                    u64::from(layout.inline_boxes.max(1)) * hdm::BOX_BYTES,
                ),
                entry(1, meta, layout.box_meta_bytes()),
                entry(
                    2,
                    ff,
                    u64::from(layout.tested) * hdm::BOX_FRAME_F64S as u64 * 8,
                ),
                entry(3, fu, u64::from(layout.tested) * 16),
                entry(4, queries, q * hdm::QUERY_BYTES),
                entry(5, shapes, n * 4),
                entry(6, answers, q * 4),
                entry(7, bc, 16),
                entry(8, box_out, n * 4),
                entry(9, resident, resident_bytes),
            ],
        })
    }

    /// The bind group of the kept planes' table passes (`sat_rows`, `sat_cols`).
    fn sat_bind_group(&self, t: &TestBuffers, layout: &WaveLayout) -> wgpu::BindGroup {
        let (Some(pyramid), Some(kept), Some(tables), Some(summary)) =
            (&t.pyramid, &t.kept, &t.tables, &t.summary)
        else {
            unreachable!("kept planes' buffers were just ensured");
        };
        let part = buffer_entry;
        let n = u64::from(layout.kept);
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("hdm summed-area table bind group"),
            layout: &self.hdm_pipelines.sat_layout,
            entries: &[
                part(10, pyramid, layout.pyramid_floats * 4),
                part(11, kept, n * hdm::KEPT_BYTES),
                part(12, tables, layout.table_words * 4),
                part(13, summary, n * hdm::SUMMARY_WORDS * 4),
            ],
        })
    }

    /// After the table passes: each kept plane's table into its texture, and the summaries
    /// into their read-back buffer.
    fn encode_kept_copies(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        t: &TestBuffers,
        buffers: &WaveBuffers,
        layout: &WaveLayout,
    ) {
        let (Some(tables), Some(summary), Some(staging)) =
            (&t.tables, &t.summary, &t.summary_staging)
        else {
            unreachable!("kept planes' buffers were just ensured");
        };
        for (plane, texture) in layout.planes.iter().zip(&buffers.kept) {
            let (Some(kp), Some(texture)) = (&plane.kept, texture) else {
                continue;
            };
            let ((width, height), _) = plane.target;
            encoder.copy_buffer_to_texture(
                wgpu::TexelCopyBufferInfo {
                    buffer: tables,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: u64::from(kp.table) * 4,
                        bytes_per_row: Some(kp.stride * 4),
                        rows_per_image: Some(height),
                    },
                },
                wgpu::TexelCopyTextureInfo {
                    texture: &texture.texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d::ZERO,
                    aspect: wgpu::TextureAspect::All,
                },
                wgpu::Extent3d {
                    width,
                    height,
                    depth_or_array_layers: 1,
                },
            );
        }
        let bytes = u64::from(layout.kept) * hdm::SUMMARY_WORDS * 4;
        encoder.copy_buffer_to_buffer(summary, 0, staging, 0, bytes);
    }

    /// Encoding step: every plane of the wave ([`Self::encode_plane`]) in one command buffer.
    fn encode(
        &self,
        pool: &Pool,
        buffers: &WaveBuffers,
        layout: &WaveLayout,
        prepared: &[Prepared],
        timestamps: Option<&Timestamps>,
    ) -> wgpu::CommandBuffer {
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("umbrasweep planes"),
            });
        if let (Some(v), true) = (buffers.views, layout.counted > 0) {
            let writes = timestamps.map(|t| t.compute_writes(layout.planes.len()));
            self.encode_views(&mut encoder, v, layout, writes);
        }
        for (w, plane) in layout.planes.iter().enumerate() {
            let writes = timestamps.map(|t| t.writes(w));
            self.encode_plane(
                &mut encoder,
                pool,
                buffers,
                (plane, &buffers.tables[w]),
                &prepared[plane.job],
                writes,
            );
        }
        self.encode_tests(&mut encoder, pool, buffers, layout);
        if let Some(t) = timestamps {
            t.resolve(&mut encoder);
        }
        encoder.finish()
    }

    /// One plane: a render pass into its target, cleared to `+inf` — one draw per chunk of
    /// occluders, then one scissored fullscreen draw per reprojection — and the copy of the
    /// target into its read-back buffer.
    fn encode_plane(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        pool: &Pool,
        buffers: &WaveBuffers,
        (plane, tables): (&PlaneLayout, &[Arc<SweepTable>]),
        p: &Prepared,
        timestamp_writes: Option<wgpu::RenderPassTimestampWrites>,
    ) {
        let (size, k) = plane.target;
        let target = &pool.targets[&size][k];
        let chunk_groups = self.chunk_bind_groups(buffers, plane, p);
        let reproject_groups = self.reprojection_bind_groups(buffers, plane, tables, p);
        let counted_group = self.counted_bind_group(buffers, plane);
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("occluder projections"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &target.view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color {
                            r: f64::INFINITY,
                            g: 0.0,
                            b: 0.0,
                            a: 0.0,
                        }),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            if !p.chunks.is_empty() {
                pass.set_pipeline(&self.pipelines.projection);
                pass.set_vertex_buffer(0, buffers.vertices.slice(..));
                let base = plane.first_vertex;
                for (c, bg) in p.chunks.iter().zip(&chunk_groups) {
                    pass.set_bind_group(0, bg, &[]);
                    pass.draw(base + c.vertices.start..base + c.vertices.end, 0..1);
                }
            }
            if let (Some(bg), Some(vp)) = (&counted_group, &self.view_pipelines) {
                let (first, count) = plane.counted;
                pass.set_pipeline(&vp.counted);
                pass.set_bind_group(0, bg, &[]);
                pass.draw(0..6, first..first + count);
            }
            if !p.sweeps.is_empty() {
                pass.set_pipeline(&self.pipelines.reproject);
                for (sw, bg) in p.sweeps.iter().zip(&reproject_groups) {
                    let [x, y, width, height] = sw.scissor;
                    pass.set_scissor_rect(x, y, width, height);
                    pass.set_bind_group(0, bg, &[]);
                    pass.draw(0..3, 0..1);
                }
            }
        }
        if plane.tested.is_some() {
            // Its map stays on the device: the occludee tests read it (`encode_tests`).
            return;
        }
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture: &target.texture,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &target.staging,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(target.padded_row),
                    rows_per_image: Some(size.1),
                },
            },
            wgpu::Extent3d {
                width: size.0,
                height: size.1,
                depth_or_array_layers: 1,
            },
        );
    }

    /// The bind groups of a plane's occluder draws, one per chunk: the plane's uniforms and
    /// the chunk's records and edges.
    fn chunk_bind_groups(
        &self,
        buffers: &WaveBuffers,
        plane: &PlaneLayout,
        p: &Prepared,
    ) -> Vec<wgpu::BindGroup> {
        p.chunks
            .iter()
            .zip(&plane.chunk_offsets)
            .map(|(c, &off)| {
                let size = ((c.data.len() as u64) * 16).max(16);
                self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("projection chunk bind group"),
                    layout: &self.pipelines.projection_layout,
                    entries: &[
                        uniforms_entry(buffers, plane),
                        wgpu::BindGroupEntry {
                            binding: 1,
                            resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                                buffer: buffers.data,
                                offset: off,
                                size: NonZeroU64::new(size),
                            }),
                        },
                    ],
                })
            })
            .collect()
    }

    /// The views pass of a wave (`shaders/views.wgsl`): one invocation per counted occluder,
    /// in workgroups of [`VIEWS_WORKGROUP`] laid out in rows of at most 65,535.
    fn encode_views(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        v: &ViewBuffers,
        layout: &WaveLayout,
        timestamp_writes: Option<wgpu::ComputePassTimestampWrites>,
    ) {
        let Some(vp) = &self.view_pipelines else {
            unreachable!("counted occluders are only prepared with the views pipelines");
        };
        fn whole(b: &Option<wgpu::Buffer>, size: u64) -> wgpu::BindingResource<'_> {
            let Some(b) = b else {
                unreachable!("the views buffers were just ensured");
            };
            wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer: b,
                offset: 0,
                size: NonZeroU64::new(size),
            })
        }
        let bg = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("views bind group"),
            layout: &vp.views_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: whole(&v.points, view_points_bytes(layout)),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: whole(&v.occ, layout.counted as u64 * 16),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: whole(&v.planes_f, (layout.planes.len() * PLANE_F64S * 8) as u64),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: whole(&v.planes_u, layout.planes.len() as u64 * 16),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: whole(&v.records, layout.counted_words as u64 * 16),
                },
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: layout
                        .parts
                        .as_ref()
                        .map_or(&vp.no_parts, |r| &*r.points.buffer)
                        .as_entire_binding(),
                },
            ],
        });
        let groups = (layout.counted as u32).div_ceil(VIEWS_WORKGROUP);
        let gx = groups.min(65_535);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("occluder views"),
            timestamp_writes,
        });
        pass.set_pipeline(&vp.views);
        pass.set_bind_group(0, &bg, &[]);
        pass.dispatch_workgroups(gx, groups.div_ceil(gx), 1);
    }

    /// The bind group of a plane's counted draw (`None` without counted occluders): its
    /// uniforms, the wave's occluders and records.
    fn counted_bind_group(
        &self,
        buffers: &WaveBuffers,
        plane: &PlaneLayout,
    ) -> Option<wgpu::BindGroup> {
        let (v, vp) = (buffers.views?, self.view_pipelines.as_ref()?);
        if plane.counted.1 == 0 {
            return None;
        }
        let (Some(occ), Some(records)) = (&v.occ, &v.records) else {
            unreachable!("the views buffers were just ensured");
        };
        Some(self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("counted bind group"),
            layout: &vp.counted_layout,
            entries: &[
                uniforms_entry(buffers, plane),
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: records.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: occ.as_entire_binding(),
                },
            ],
        }))
    }

    /// The bind groups of a plane's reprojection draws, one per reprojection: its windows and
    /// its summed-area table.
    fn reprojection_bind_groups(
        &self,
        buffers: &WaveBuffers,
        plane: &PlaneLayout,
        tables: &[Arc<SweepTable>],
        p: &Prepared,
    ) -> Vec<wgpu::BindGroup> {
        p.sweeps
            .iter()
            .zip(tables)
            .zip(&plane.window_offsets)
            .map(|((sw, t), &off)| {
                let Some(buf) = buffers.windows else {
                    unreachable!("the windows buffer exists when a plane reprojects");
                };
                self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("reprojection bind group"),
                    layout: &self.pipelines.reproject_layout,
                    entries: &[
                        wgpu::BindGroupEntry {
                            binding: 0,
                            resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                                buffer: buf,
                                offset: off,
                                size: NonZeroU64::new(sw.words.len() as u64 * 8),
                            }),
                        },
                        wgpu::BindGroupEntry {
                            binding: 1,
                            resource: wgpu::BindingResource::TextureView(&t.view),
                        },
                    ],
                })
            })
            .collect()
    }

    /// Submission step: submits `commands` and maps every plane's read-back buffer; each
    /// mapping reports `(plane index in the wave, result)` on the returned channel.
    fn submit(
        &self,
        pool: &Pool,
        layout: &WaveLayout,
        commands: wgpu::CommandBuffer,
        timestamps: Option<&Timestamps>,
    ) -> (wgpu::SubmissionIndex, Mapped) {
        let submission = self.submit_commands(commands);
        let (tx, rx) = mpsc::channel();
        // Each mapping reports its own index, 0 .. `layout.mappings(..)`.
        let mut w = 0;
        let mut map = |buffer: &wgpu::Buffer, bytes: u64| {
            let tx = tx.clone();
            let index = w;
            w += 1;
            buffer.map_async(wgpu::MapMode::Read, ..bytes, move |r| {
                let _ = tx.send((index, r));
            });
        };
        if let Some(t) = timestamps {
            for (k, set) in t.sets.iter().enumerate() {
                map(&set.read_back, t.bytes(k));
            }
        }
        for plane in layout.planes.iter().filter(|p| p.tested.is_none()) {
            let (size, k) = plane.target;
            let staging = &pool.targets[&size][k].staging;
            map(staging, staging.size());
        }
        let tests = pool.tests.as_ref();
        if let Some(staging) = tests.and_then(|t| t.staging.as_ref())
            && layout.tested > 0
        {
            map(staging, (u64::from(layout.answers()) * 4).max(4));
        }
        if let Some(staging) = tests.and_then(|t| t.summary_staging.as_ref())
            && layout.kept > 0
        {
            map(staging, u64::from(layout.kept) * hdm::SUMMARY_WORDS * 4);
        }
        (submission, rx)
    }

    /// Waiting step: polls the device ([`Self::poll_until`]) until all `planes` read-back
    /// buffers are mapped.
    ///
    /// # Errors
    /// As [`Self::poll_until`].
    fn wait(
        &self,
        submission: &wgpu::SubmissionIndex,
        mapped: Mapped,
        planes: usize,
    ) -> Result<(), BackendError> {
        let mut done = vec![false; planes];
        let mut remaining = planes;
        self.poll_until(submission, &format!("{planes} planes"), || {
            while let Ok((w, r)) = mapped.try_recv() {
                r.map_err(|e| BackendError::ReadBack {
                    step: "read-back failed",
                    message: e.to_string(),
                })?;
                if !done[w] {
                    done[w] = true;
                    remaining -= 1;
                }
            }
            Ok(remaining == 0)
        })
    }

    /// Submits `commands` on the queue. Any number of threads submit and poll at once: no lock
    /// serialises them ([`Self::poll_until`] says why none is needed), unless
    /// [`GpuBackend::set_serial_polls`](super::GpuBackend::set_serial_polls) asked for it.
    pub(super) fn submit_commands(&self, commands: wgpu::CommandBuffer) -> wgpu::SubmissionIndex {
        let _turn = self.serial_turn();
        self.queue.submit([commands])
    }

    /// Polls the device until `done` says the work of `submission` (its read-backs mapped) is
    /// over, checking for a lost device between polls. `work` names the work in a timeout's
    /// message.
    ///
    /// Every poll is non-blocking ([`wgpu::PollType::Poll`]): it retires what the device has
    /// finished and runs the mapping callbacks, for this thread's submissions and any other's.
    /// Between polls the thread yields for [`POLL_SPIN`], then sleeps for an eighth of the time
    /// waited so far ([`POLL_PAUSE`] bounds it). A *blocking* poll for one submission
    /// ([`wgpu::PollType::Wait`] with an index and a timeout) is what this avoids: wgpu-core 30
    /// asserts in `Device::maintain` when another thread's submission or poll retires a
    /// submission between that poll's timed-out look at the fence and its look at the queue
    /// ("If the queue is empty, the current submission index …", gfx-rs/wgpu#9958; cells baked
    /// on several threads hit it in CI, and `tests/gpu.rs` does within seconds). Such polls are
    /// safe only with one lock around every submission and poll, and a poll holds the lock
    /// while it blocks, so no other thread can submit until the device has finished the work
    /// waited for: the threads' submissions run one at a time, and a device with many cells in
    /// flight sits idle between them. That is the serial way
    /// ([`GpuBackend::set_serial_polls`](super::GpuBackend::set_serial_polls)), kept to measure
    /// the difference. A non-blocking poll has no index to assert on.
    ///
    /// # Errors
    /// The recorded failure ([`BackendError::DeviceLost`], [`BackendError::Uncaptured`]) on
    /// the backend's own device; [`BackendError::PollFailed`] on a failed poll (an engine's
    /// lost device); `done`'s errors (a failed mapping); [`BackendError::Timeout`] when
    /// [`DEADLINE`] passes — never a hang.
    pub(super) fn poll_until(
        &self,
        submission: &wgpu::SubmissionIndex,
        work: &str,
        mut done: impl FnMut() -> Result<bool, BackendError>,
    ) -> Result<(), BackendError> {
        let start = Instant::now();
        loop {
            self.check_failure()?;
            let polled = match self.serial_turn() {
                Some(_turn) => self.device.poll(wgpu::PollType::Wait {
                    submission_index: Some(submission.clone()),
                    timeout: Some(SERIAL_POLL_SLICE),
                }),
                None => self.device.poll(wgpu::PollType::Poll),
            };
            match polled {
                Ok(_) | Err(wgpu::PollError::Timeout) => {}
                Err(e) => {
                    self.check_failure()?;
                    // Without a device-lost callback (an engine's device), a lost device shows
                    // here: the submission was refused.
                    return Err(BackendError::PollFailed {
                        message: e.to_string(),
                    });
                }
            }
            if done()? {
                return Ok(());
            }
            let waited = start.elapsed();
            if waited > DEADLINE {
                return Err(BackendError::Timeout {
                    work: work.to_string(),
                    deadline: DEADLINE,
                });
            }
            // The serial way's poll blocked; a non-blocking one pauses before the next.
            if self.serial_polls.is_none() {
                pause(waited);
            }
        }
    }

    /// The serial way's turn ([`GpuBackend::set_serial_polls`](super::GpuBackend::set_serial_polls)):
    /// its lock, held around one submission or poll; `None` in the default concurrent way.
    fn serial_turn(&self) -> Option<std::sync::MutexGuard<'_, ()>> {
        (self.serial_polls.as_ref()).map(|m| m.lock().unwrap_or_else(|e| e.into_inner()))
    }

    /// Makes `slot` a buffer of at least `size` bytes (grown to a power of two, never shrunk).
    ///
    /// # Errors
    /// [`BackendError::BufferTooLarge`] when `size` exceeds the device's largest buffer.
    pub(super) fn ensure_buffer(
        &self,
        slot: &mut Option<wgpu::Buffer>,
        size: u64,
        usage: wgpu::BufferUsages,
        label: &'static str,
    ) -> Result<(), BackendError> {
        if slot.as_ref().is_some_and(|b| b.size() >= size) {
            return Ok(());
        }
        let max_buffer = self.limits.max_buffer;
        if size > max_buffer {
            return Err(BackendError::BufferTooLarge {
                label,
                size,
                max: max_buffer,
            });
        }
        let cap = size
            .next_power_of_two()
            .clamp(1 << 16, max_buffer.max(size));
        if let Some(old) = slot.take() {
            old.destroy();
        }
        *slot = Some(self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: cap,
            usage,
            mapped_at_creation: false,
        }));
        Ok(())
    }

    /// A `width × height` single-channel 2D texture and its view, labelled `name w×h`.
    fn map_texture(
        &self,
        name: &str,
        (width, height): (u32, u32),
        format: wgpu::TextureFormat,
        usage: wgpu::TextureUsages,
    ) -> (wgpu::Texture, wgpu::TextureView) {
        let texture = self.device.create_texture(&wgpu::TextureDescriptor {
            label: Some(&format!("{name} {width}×{height}")),
            size: wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor {
            label: Some(&format!("{name} {width}×{height} view")),
            ..Default::default()
        });
        (texture, view)
    }

    /// A `w × h` Depth Map target (`R32Float`) and its read-back buffer (rows padded to
    /// [`wgpu::COPY_BYTES_PER_ROW_ALIGNMENT`]).
    fn new_target(&self, (w, h): (u32, u32)) -> Target {
        let (texture, view) = self.map_texture(
            "depth map",
            (w, h),
            wgpu::TextureFormat::R32Float,
            wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::COPY_SRC
                | wgpu::TextureUsages::TEXTURE_BINDING,
        );
        let padded_row = (w * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(&format!("depth map {w}×{h} read-back")),
            size: padded_row as u64 * h as u64,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Target {
            view,
            texture,
            staging,
            padded_row,
        }
    }

    /// A summed-area table texture (`R32Uint`) for a source of `size`.
    fn new_sweep_table(&self, size: (u32, u32)) -> SweepTable {
        let (texture, view) = self.map_texture(
            "reprojection table",
            size,
            wgpu::TextureFormat::R32Uint,
            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        );
        SweepTable {
            texture,
            view,
            size,
        }
    }
}

/// The read-back mappings' reports: `(plane index in the wave, result)`.
type Mapped = mpsc::Receiver<(usize, Result<(), wgpu::BufferAsyncError>)>;

/// Timestamps one query set holds (wgpu's largest set): two per render pass, its start and
/// end.
const TIMESTAMPS_PER_SET: usize = wgpu::QUERY_SET_MAX_QUERIES as usize;

/// The query sets a wave of `passes` render passes needs.
fn timestamp_sets(passes: usize) -> usize {
    (2 * passes).div_ceil(TIMESTAMPS_PER_SET)
}

/// One pooled query set of [`TIMESTAMPS_PER_SET`] timestamps, the buffer it is resolved into
/// and the mappable copy read back.
struct TimestampSet {
    set: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    read_back: wgpu::Buffer,
}

impl TimestampSet {
    fn new(device: &wgpu::Device) -> Self {
        let bytes = TIMESTAMPS_PER_SET as u64 * 8;
        let buffer = |label, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes,
                usage,
                mapped_at_creation: false,
            })
        };
        TimestampSet {
            set: device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("pass timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: TIMESTAMPS_PER_SET as u32,
            }),
            resolved: buffer(
                "resolved timestamps",
                wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            ),
            read_back: buffer(
                "timestamps read-back",
                wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            ),
        }
    }
}

/// A wave's GPU timestamps: the pooled sets it uses, for its `passes` render passes.
struct Timestamps<'a> {
    sets: &'a [TimestampSet],
    passes: usize,
    /// Nanoseconds per tick.
    period: f64,
}

impl Timestamps<'_> {
    /// The timestamps the wave writes into set `k`.
    fn queries(&self, k: usize) -> u32 {
        (2 * self.passes - k * TIMESTAMPS_PER_SET).min(TIMESTAMPS_PER_SET) as u32
    }

    /// The bytes of set `k`'s timestamps.
    fn bytes(&self, k: usize) -> u64 {
        u64::from(self.queries(k)) * 8
    }

    /// The start and end timestamps of render pass `w`.
    fn writes(&self, w: usize) -> wgpu::RenderPassTimestampWrites<'_> {
        let (k, i) = ((2 * w) / TIMESTAMPS_PER_SET, (2 * w) % TIMESTAMPS_PER_SET);
        wgpu::RenderPassTimestampWrites {
            query_set: &self.sets[k].set,
            beginning_of_pass_write_index: Some(i as u32),
            end_of_pass_write_index: Some(i as u32 + 1),
        }
    }

    /// The start and end timestamps of pass `w` when it is a compute pass (the views pass).
    fn compute_writes(&self, w: usize) -> wgpu::ComputePassTimestampWrites<'_> {
        let r = self.writes(w);
        wgpu::ComputePassTimestampWrites {
            query_set: r.query_set,
            beginning_of_pass_write_index: r.beginning_of_pass_write_index,
            end_of_pass_write_index: r.end_of_pass_write_index,
        }
    }

    /// Resolves the wave's timestamps and copies them to the mappable buffers.
    fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        for (k, s) in self.sets.iter().enumerate() {
            encoder.resolve_query_set(&s.set, 0..self.queries(k), &s.resolved, 0);
            encoder.copy_buffer_to_buffer(&s.resolved, 0, &s.read_back, 0, self.bytes(k));
        }
    }

    /// The summed GPU time of the wave's passes and the time of its last pass (mapped
    /// buffers), unmapping them.
    ///
    /// # Errors
    /// [`BackendError::ReadBack`] when a mapped range cannot be read.
    fn read(&self) -> Result<(Duration, Duration), BackendError> {
        let mut ticks: Vec<u64> = Vec::with_capacity(2 * self.passes);
        for (k, s) in self.sets.iter().enumerate() {
            let bytes = s
                .read_back
                .slice(..self.bytes(k))
                .get_mapped_range()
                .map_err(|e| BackendError::ReadBack {
                    step: "read-back mapping",
                    message: e.to_string(),
                })?;
            ticks.extend(
                bytes
                    .chunks_exact(8)
                    .map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes"))),
            );
            drop(bytes);
            s.read_back.unmap();
        }
        let per_pass: Vec<u64> = ticks
            .chunks_exact(2)
            .map(|p| p[1].saturating_sub(p[0]))
            .collect();
        let time = |t: u64| Duration::from_nanos((t as f64 * self.period).round() as u64);
        Ok((
            time(per_pass.iter().sum()),
            time(per_pass.last().copied().unwrap_or(0)),
        ))
    }
}

/// Read-back step: every plane's Depth Map from its mapped read-back buffer (padded rows
/// dropped), the buffer unmapped, the slice mask merged, into `out[job]`.
///
/// # Errors
/// [`BackendError::ReadBack`] when a mapped range cannot be read.
fn read_back(
    pool: &Pool,
    layout: &WaveLayout,
    prepared: &[Prepared],
    out: &mut [Option<PlaneResult>],
) -> Result<(), BackendError> {
    for plane in layout.planes.iter().filter(|p| p.tested.is_none()) {
        let ((width, height), k) = plane.target;
        let target = &pool.targets[&(width, height)][k];
        let mut map = DepthMap {
            width,
            height,
            depth: Vec::with_capacity(width as usize * height as usize),
        };
        {
            let view = target
                .staging
                .get_mapped_range(..)
                .map_err(|e| BackendError::ReadBack {
                    step: "read-back mapping",
                    message: e.to_string(),
                })?;
            let row_bytes = width as usize * 4;
            for row in view.chunks(target.padded_row as usize) {
                map.depth
                    .extend_from_slice(bytemuck::cast_slice::<u8, f32>(&row[..row_bytes]));
            }
        }
        target.staging.unmap();
        if let Some(mask) = &prepared[plane.job].mask {
            merge_mask(&mut map, mask);
        }
        out[plane.job] = Some(PlaneResult::Map(map));
    }
    Ok(())
}

/// The first `bytes` of a mapped read-back buffer as `u32` words; the buffer is unmapped.
///
/// # Errors
/// [`BackendError::ReadBack`] (naming `step`) when the mapped range cannot be read.
fn mapped_words(
    staging: &wgpu::Buffer,
    bytes: u64,
    step: &'static str,
) -> Result<Vec<u32>, BackendError> {
    let words = {
        let view = staging
            .get_mapped_range(..bytes)
            .map_err(|e| BackendError::ReadBack {
                step,
                message: e.to_string(),
            })?;
        bytemuck::cast_slice::<u8, u32>(&view).to_vec()
    };
    staging.unmap();
    Ok(words)
}

/// A bind group entry for the first `bytes` of `buffer` (at least 16: the buffers grow in
/// powers of two, past what a device's largest binding may be, so each binding is just the
/// wave's part).
fn buffer_entry(binding: u32, buffer: &wgpu::Buffer, bytes: u64) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry {
        binding,
        resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
            buffer,
            offset: 0,
            size: NonZeroU64::new(bytes.max(16)),
        }),
    }
}

/// Read-back step of the occludee tests: each tested plane's answers (`shaders/hdm.wgsl`'s
/// codes) into `out`.
///
/// # Errors
/// [`BackendError::ReadBack`] when the mapped range cannot be read or holds an unknown code.
fn read_answers(
    pool: &Pool,
    layout: &WaveLayout,
    out: &mut [Option<PlaneResult>],
) -> Result<(), BackendError> {
    let Some(staging) = pool
        .tests
        .as_ref()
        .and_then(|t| t.staging.as_ref())
        .filter(|_| layout.tested > 0)
    else {
        return Ok(());
    };
    let bytes = (u64::from(layout.answers()) * 4).max(4);
    let mut codes = mapped_words(staging, bytes, "answers mapping")?;
    codes.truncate(layout.answers() as usize);
    for plane in &layout.planes {
        let Some(tp) = &plane.tested else { continue };
        let (first, rects) = (tp.rects.0 as usize, tp.rects.1 as usize);
        let first_box = (layout.rects + tp.boxes.0) as usize;
        let answers = codes[first..first + rects]
            .iter()
            .chain(&codes[first_box..first_box + tp.boxes.1 as usize])
            .map(|&c| match c {
                0 => Ok(Coverage::Partial),
                1 => Ok(Coverage::Hidden),
                2 => Ok(Coverage::Empty),
                _ => Err(BackendError::ReadBack {
                    step: "answers",
                    message: format!("unknown answer code {c}"),
                }),
            })
            .collect::<Result<Vec<_>, _>>()?;
        out[plane.job] = Some(PlaneResult::Answers(answers));
    }
    Ok(())
}

impl GpuBackend {
    /// Read-back step of the kept planes: each one's summary, its answers (already in `out`)
    /// turned into [`PlaneResult::Kept`], its table texture cached for a new stand-in of its
    /// map (or, without umbra, given back to the free list: nothing reprojects from it).
    ///
    /// # Errors
    /// [`BackendError::ReadBack`] when the mapped range cannot be read.
    fn read_kept(
        &self,
        pool: &Pool,
        layout: &WaveLayout,
        jobs: &[PlaneJob],
        textures: Vec<Option<SweepTable>>,
        out: &mut [Option<PlaneResult>],
    ) -> Result<(), BackendError> {
        let Some(staging) = pool
            .tests
            .as_ref()
            .and_then(|t| t.summary_staging.as_ref())
            .filter(|_| layout.kept > 0)
        else {
            return Ok(());
        };
        let bytes = u64::from(layout.kept) * hdm::SUMMARY_WORDS * 4;
        let words = mapped_words(staging, bytes, "kept planes' summaries mapping")?;
        for (plane, texture) in layout.planes.iter().zip(textures) {
            let (Some(kp), Some(texture)) = (&plane.kept, texture) else {
                continue;
            };
            let w = kp.index as usize * hdm::SUMMARY_WORDS as usize;
            let (umbra, outside_umbra) = hdm::read_summary(&words[w..w + 8]);
            let f = &jobs[plane.job].frame;
            let source = Arc::new(DepthMap::on_device(f.width, f.height));
            let table = match umbra {
                Some(_) => Some(Arc::new(texture)),
                None => {
                    self.tables.give_back(texture);
                    None
                }
            };
            self.tables.insert(&source, Cached { table, umbra });
            let Some(PlaneResult::Answers(answers)) = out[plane.job].take() else {
                unreachable!("a kept plane is a tested one");
            };
            out[plane.job] = Some(PlaneResult::Kept(KeptMap {
                answers,
                source,
                umbra,
                outside_umbra,
            }));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A wave of more passes than one query set holds spreads its timestamps over several,
    /// the last one partly used.
    #[test]
    fn timestamps_fill_query_sets_in_order() {
        assert_eq!(timestamp_sets(0), 0);
        assert_eq!(timestamp_sets(1), 1);
        assert_eq!(timestamp_sets(TIMESTAMPS_PER_SET / 2), 1);
        assert_eq!(timestamp_sets(TIMESTAMPS_PER_SET / 2 + 1), 2);
        let t = Timestamps {
            sets: &[],
            passes: TIMESTAMPS_PER_SET / 2 + 1,
            period: 1.0,
        };
        assert_eq!(t.queries(0) as usize, TIMESTAMPS_PER_SET);
        assert_eq!(t.queries(1), 2);
        assert_eq!(t.bytes(1), 16);
    }

    /// `views.wgsl` reads the resident parts' flag where the wave writes it (the constant's
    /// place between the count and the plane index is checked where it is defined).
    #[test]
    fn the_views_shader_agrees_with_the_resident_flag() {
        let src = super::super::VIEWS_WGSL;
        assert!(src.contains(&format!(
            "const RESIDENT_POINTS: u32 = 0x{RESIDENT_POINTS:x}u;"
        )));
        assert!(src.contains("let n = min(o.y & 0x7fu, MAXP);"));
        assert!(src.contains(&format!(
            "const MAXP: u32 = {}u;",
            super::super::prepare::COUNTED_MAX_POINTS
        )));
    }
}
