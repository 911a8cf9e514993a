//! The raster work of a bake — occluder extended projections, Depth Maps, and ray space
//! factorization's charts ([`RsfCharts`]) — behind one trait, so that the CPU backend
//! ([`cpu`]) and the wgpu backend ([`gpu`]) give the same answers.
//!
//! Every backend implements the raster contract stated in [`crate::plane`]: a
//! [`plane::PlaneJob`] in, a [`plane::DepthMap`] out, occluders covering only whole pixels
//! inside all 8 views, slices, and the exact reprojection filter. The part of the work both
//! backends share — the occluder's Projection polygon, the slice fill and the contract's
//! brute-force definition — is [`coverage`]; each backend only rasterises the polygons its own
//! way (spans on the CPU, a fragment shader on the GPU).
//!
//! The result may differ between backends only on pixels where a view's edge passes within a
//! rounding error of a pixel corner.

pub mod coverage;
pub mod cpu;
pub mod gpu;

use crate::geom::DAabb;
use crate::plane;
use crate::rsf::{RayCharts, RsfWork, Umbra};
use glam::DVec3;
use std::borrow::Cow;
use std::ops::Range;

/// Why a backend could not start or could not render.
///
/// The variants fall in four groups, each handled its own way:
/// * **No adapter** ([`NoAdapter`](Self::NoAdapter)): there is no GPU to use; fall back to
///   the CPU backend ([`cpu::CpuBackend`]), which gives the same results.
/// * **The device does not suit the backend** ([`CreateDevice`](Self::CreateDevice),
///   [`MissingFeatures`](Self::MissingFeatures), [`LimitTooLow`](Self::LimitTooLow),
///   [`UniformAlignment`](Self::UniformAlignment)): only when the backend is created; create
///   the device as the message says, or fall back to the CPU.
/// * **The jobs do not fit the device** ([`PlaneSize`](Self::PlaneSize),
///   [`BadReprojection`](Self::BadReprojection), [`BufferTooLarge`](Self::BufferTooLarge),
///   [`OccluderTooLarge`](Self::OccluderTooLarge)): refused before anything is drawn and the
///   backend stays usable; lower the resolution or the occluders' detail, or render those jobs
///   on the CPU.
/// * **The device failed** ([`DeviceLost`](Self::DeviceLost),
///   [`OutOfMemory`](Self::OutOfMemory), [`Validation`](Self::Validation),
///   [`Uncaptured`](Self::Uncaptured), [`PollFailed`](Self::PollFailed),
///   [`ReadBack`](Self::ReadBack), [`Timeout`](Self::Timeout)): the call's results are lost
///   (never partial) and, for a lost device, so is every later call;
///   [`device_failed`](Self::device_failed) says so. Drop the backend and create a new one, or
///   fall back to the CPU.
///
/// The messages are those the backend always printed: `no GPU adapter found: …` for
/// [`NoAdapter`](Self::NoAdapter), `GPU error: …` for the rest.
#[derive(Clone, Debug, thiserror::Error)]
pub enum BackendError {
    /// No usable GPU adapter; the message says why (none found, or none with the needed
    /// features).
    ///
    /// **When this occurs:** [`gpu::GpuBackend::new`] on a machine without a Vulkan, Metal or
    /// DX12 adapter, or whose adapters all lack `FLOAT32_BLENDABLE`.
    ///
    /// **How to handle:** use the CPU backend; on Linux without a GPU, Mesa's software Vulkan
    /// driver (`mesa-vulkan-drivers`) provides an adapter.
    #[error("no GPU adapter found: {0}")]
    NoAdapter(String),
    /// The adapter refused to create the backend's device.
    ///
    /// **When this occurs:** [`gpu::GpuBackend::new`], when `request_device` fails on the best
    /// adapter (driver error, out of memory).
    ///
    /// **How to handle:** use the CPU backend, or another adapter (`WGPU_BACKEND`).
    #[error("GPU error: cannot create a device on {adapter}: {message}")]
    CreateDevice {
        /// The adapter's name.
        adapter: String,
        /// wgpu's message.
        message: String,
    },
    /// The device lacks a feature the backend needs.
    ///
    /// **When this occurs:** [`gpu::GpuBackend::with_device`] on a device created without
    /// [`gpu::GpuBackend::REQUIRED_FEATURES`]; [`gpu::GpuBackend::set_projection`] with
    /// [`gpu::GpuProjection::Counting`] on a device without `SHADER_F64` (the backend keeps
    /// its projection).
    ///
    /// **How to handle:** request `missing` in the `DeviceDescriptor`'s `required_features`
    /// (`adapter.features()` says whether the adapter has them).
    #[error(
        "GPU error: the device lacks the feature(s) {missing:?}: request them in the \
         DeviceDescriptor's required_features (adapter.features() says whether the adapter has \
         them)"
    )]
    MissingFeatures {
        /// The required features the device lacks.
        missing: wgpu::Features,
    },
    /// A device limit is below what the backend's pipelines need.
    ///
    /// **When this occurs:** [`gpu::GpuBackend::with_device`] on a device created with limits
    /// below WebGPU's defaults (e.g. WebGL2's, without storage buffers).
    ///
    /// **How to handle:** request at least [`wgpu::Limits::default`] in the
    /// `DeviceDescriptor`'s `required_limits`.
    #[error(
        "GPU error: the device's {limit} is {value}, the GPU backend needs at least {need}: \
         request at least wgpu::Limits::default() (WebGPU's defaults) in the DeviceDescriptor's \
         required_limits"
    )]
    LimitTooLow {
        /// The limit's name in [`wgpu::Limits`].
        limit: &'static str,
        /// The device's value.
        value: u64,
        /// The least the backend needs.
        need: u64,
    },
    /// The device's uniform offset alignment does not divide the backend's uniform stride.
    ///
    /// **When this occurs:** [`gpu::GpuBackend::with_device`] on a device whose
    /// `min_uniform_buffer_offset_alignment` exceeds WebGPU's maximum of 256.
    ///
    /// **How to handle:** request WebGPU's default alignment (256) or less.
    #[error(
        "GPU error: the device's min_uniform_buffer_offset_alignment is {align}, the GPU \
         backend needs a divisor of {stride} (WebGPU allows at most 256)"
    )]
    UniformAlignment {
        /// The device's `min_uniform_buffer_offset_alignment`.
        align: u64,
        /// The stride between planes' uniforms, which it must divide.
        stride: u64,
    },
    /// A plane (or a reprojection's source) is larger than the device's textures, or empty.
    ///
    /// **When this occurs:** [`RasterBackend::render`] on the GPU backend, before any work,
    /// for a job whose frame is outside `1..=max` pixels per side.
    ///
    /// **How to handle:** lower the resolution (or `max_stretch`), or render the job on the
    /// CPU; the backend stays usable.
    #[error(
        "GPU error: plane size {width} × {height} is outside 1..={max} per side supported by \
         {adapter}"
    )]
    PlaneSize {
        /// The plane's width in pixels.
        width: u32,
        /// The plane's height in pixels.
        height: u32,
        /// The largest side the device supports.
        max: u32,
        /// The adapter's name.
        adapter: String,
    },
    /// A job's reprojection does not match its plane or its own source.
    ///
    /// **When this occurs:** [`RasterBackend::render`] on the GPU backend, before any work, when
    /// a reprojection's source is too large or empty, or its depth, column or row windows do
    /// not have the sizes of the source and the plane.
    ///
    /// **How to handle:** a bug in the caller that built the job; the backend stays usable.
    #[error(
        "GPU error: a reprojection onto a {width} × {height} plane has a {source_width} × \
         {source_height} source with {source_pixels} pixels, {cols} column and {rows} row \
         windows"
    )]
    BadReprojection {
        /// The plane's width.
        width: u32,
        /// The plane's height.
        height: u32,
        /// The source's width.
        source_width: u32,
        /// The source's height.
        source_height: u32,
        /// The number of depths the source holds.
        source_pixels: usize,
        /// The number of column windows (the plane's width when valid).
        cols: usize,
        /// The number of row windows (the plane's height when valid).
        rows: usize,
    },
    /// One of the backend's buffers would exceed the device's largest buffer.
    ///
    /// **When this occurs:** [`RasterBackend::render`] on the GPU backend, when one plane's
    /// data (vertices, reprojection windows, summed-area tables) is too large for a buffer.
    ///
    /// **How to handle:** lower the resolution or the occluders' detail, or render on the CPU.
    #[error("GPU error: {label}: {size} bytes exceed the device's maximum buffer size {max}")]
    BufferTooLarge {
        /// The buffer's label.
        label: &'static str,
        /// The bytes needed.
        size: u64,
        /// The device's `max_buffer_size`.
        max: u64,
    },
    /// One occluder's data exceed a storage binding.
    ///
    /// **When this occurs:** [`RasterBackend::render`] on the GPU backend, for an occluder
    /// with more edges than `max_storage_buffer_binding_size` holds.
    ///
    /// **How to handle:** simplify the occluder, or render on the CPU.
    #[error("GPU error: an occluder has {edges} edges, more than one storage binding holds")]
    OccluderTooLarge {
        /// The occluder's number of edges.
        edges: usize,
    },
    /// The backend's own device was lost (driver reset, `destroy`, …).
    ///
    /// **When this occurs:** any call after the device-lost callback fired.
    ///
    /// **How to handle:** every later call fails too: drop the backend and create a new one.
    #[error("GPU error: device lost ({reason:?}): {message}")]
    DeviceLost {
        /// wgpu's reason.
        reason: wgpu::DeviceLostReason,
        /// wgpu's message.
        message: String,
    },
    /// The device ran out of memory (caught by an error scope).
    ///
    /// **When this occurs:** creating the pipelines, or a render whose wave's buffers and
    /// targets do not fit.
    ///
    /// **How to handle:** render fewer jobs per call or at a lower resolution; the backend may
    /// stay usable.
    #[error("GPU error: out of GPU memory: {message}")]
    OutOfMemory {
        /// wgpu's message.
        message: String,
    },
    /// The device reported a validation error (caught by an error scope): a bug in the
    /// backend, or a device that does not support what it claims.
    ///
    /// **When this occurs:** creating the pipelines, or a render.
    ///
    /// **How to handle:** report it; fall back to the CPU.
    #[error("GPU error: GPU validation error: {message}")]
    Validation {
        /// wgpu's message.
        message: String,
    },
    /// An error no error scope caught reached the backend's own device's handler.
    ///
    /// **When this occurs:** any call after the handler fired (backend's own device only).
    ///
    /// **How to handle:** drop the backend and create a new one, or fall back to the CPU.
    #[error("GPU error: uncaptured GPU error: {message}")]
    Uncaptured {
        /// wgpu's message.
        message: String,
    },
    /// Polling the device failed: on an engine's device (no device-lost callback), a lost
    /// device shows here.
    ///
    /// **When this occurs:** [`RasterBackend::render`], while waiting for the GPU.
    ///
    /// **How to handle:** as [`DeviceLost`](Self::DeviceLost).
    #[error("GPU error: poll failed (is the device lost?): {message}")]
    PollFailed {
        /// wgpu's message.
        message: String,
    },
    /// Mapping or reading a read-back buffer failed.
    ///
    /// **When this occurs:** [`RasterBackend::render`], after the GPU finished, typically on a
    /// lost device.
    ///
    /// **How to handle:** as [`DeviceLost`](Self::DeviceLost).
    #[error("GPU error: {step}: {message}")]
    ReadBack {
        /// What failed: `read-back failed` (the mapping) or `read-back mapping` (the mapped
        /// range).
        step: &'static str,
        /// wgpu's message.
        message: String,
    },
    /// The GPU did not finish a wave of planes in time; never a hang.
    ///
    /// **When this occurs:** [`RasterBackend::render`] or a GPU [`RsfCharts`] call, on a hung
    /// or far too slow device.
    ///
    /// **How to handle:** as [`DeviceLost`](Self::DeviceLost).
    #[error("GPU error: the GPU did not finish {work} within {deadline:?}")]
    Timeout {
        /// The work waited for (`3 planes`, `a ray-space wave`).
        work: String,
        /// How long the backend waited.
        deadline: std::time::Duration,
    },
}

impl BackendError {
    /// True when the device failed while working (lost, out of memory, validation or
    /// uncaptured error, failed poll or read-back, timeout): the call's results are lost and
    /// the backend may be unusable. False for a missing adapter, an unsuitable device, or jobs
    /// refused before any work.
    pub fn device_failed(&self) -> bool {
        matches!(
            self,
            BackendError::DeviceLost { .. }
                | BackendError::OutOfMemory { .. }
                | BackendError::Validation { .. }
                | BackendError::Uncaptured { .. }
                | BackendError::PollFailed { .. }
                | BackendError::ReadBack { .. }
                | BackendError::Timeout { .. }
        )
    }
}

/// What a backend did over its calls ([`RasterBackend::counters`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BackendCounters {
    /// Render passes.
    pub passes: usize,
    /// Bytes sent to the device.
    pub bytes_uploaded: u64,
    /// Bytes read back from the device.
    pub bytes_read_back: u64,
    /// Depth Maps read back, and sweep planes' maps kept on the device instead
    /// ([`RasterBackend::render_kept`]).
    pub maps_read_back: usize,
    /// See `maps_read_back`.
    pub maps_kept: usize,
    /// Wall time of the CPU's setup of the jobs.
    pub setup: std::time::Duration,
    /// Wall time of the device's section, from the first upload to the last read-back.
    pub gpu: std::time::Duration,
    /// GPU time of the render passes from the device's timestamps, where it has them.
    pub pass_time: Option<std::time::Duration>,
}

impl BackendCounters {
    /// What happened between `before` and `self`, two snapshots of the same backend's
    /// counters, `before` taken first (otherwise the differences saturate at zero).
    pub fn since(&self, before: &BackendCounters) -> BackendCounters {
        BackendCounters {
            passes: self.passes.saturating_sub(before.passes),
            bytes_uploaded: self.bytes_uploaded.saturating_sub(before.bytes_uploaded),
            bytes_read_back: self.bytes_read_back.saturating_sub(before.bytes_read_back),
            maps_read_back: self.maps_read_back.saturating_sub(before.maps_read_back),
            maps_kept: self.maps_kept.saturating_sub(before.maps_kept),
            setup: self.setup.saturating_sub(before.setup),
            gpu: self.gpu.saturating_sub(before.gpu),
            pass_time: self
                .pass_time
                .map(|t| t.saturating_sub(before.pass_time.unwrap_or_default())),
        }
    }
}

/// A bake asks a plane's occludee tests of a backend's device (and an occlusion sweep's
/// plane stays there) only while its box tests number at most one per this many pixels of its
/// map; past that the map comes back instead
/// ([`RasterBackend::pixels_per_device_test`]). Recording a box test costs the CPU about
/// 0.25 µs (the walk that lists the boxes, and their standard Projections' extents to leave
/// out those beside the plane; the device computes the rectangles it tests), reading a map
/// back and building its pyramid 2–5 ns per pixel (`Hdm::build` of a 256 × 256 map 0.11 ms);
/// on lavapipe, whose compute passes run on the same CPU, the paper-size forest's middle cell
/// (`bake … --sweep --backend gpu`) took 1,170, 1,228 and 1,532 ms at one test per 64, 16 and
/// 4 pixels (medians of three runs), so 64 stays the default; a real GPU answers the tests
/// in microseconds and may want fewer pixels per test (`--pixels-per-device-test`).
pub const PIXELS_PER_DEVICE_TEST: usize = 64;

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
    /// Totals over every call since the backend was created, where the backend keeps them
    /// (the GPU backend): for benchmarks, which take the difference around a bake.
    fn counters(&self) -> Option<BackendCounters> {
        None
    }
    /// Rasterises the jobs' occluder Projections and slices into one Depth Map per job, in
    /// order. Jobs are independent; a backend may run them in any order or concurrently.
    ///
    /// # Errors
    /// [`BackendError`] when the device fails; never a partial result.
    fn render(&self, jobs: &[plane::PlaneJob]) -> Result<Vec<plane::DepthMap>, BackendError>;
    /// Renders `jobs` as [`Self::render`] does, with occludee tests: `queries[k]` holds job
    /// `k`'s rectangle and box tests (`None`: its map is wanted). A backend answers a job's
    /// queries on the device where it can ([`plane::PlaneResult::Answers`], in the order of
    /// [`plane::PlaneQueries`], each exactly as [`crate::hdm::Hdm::answer`] or
    /// [`crate::project::occludee::box_coverage`] answers it on the job's map) and gives back
    /// its map otherwise. The default gives back every map.
    ///
    /// # Errors
    /// As [`Self::render`].
    fn render_tested(
        &self,
        jobs: &[plane::PlaneJob],
        queries: &[Option<plane::PlaneQueries>],
    ) -> Result<Vec<plane::PlaneResult>, BackendError> {
        debug_assert_eq!(jobs.len(), queries.len());
        Ok(self
            .render(jobs)?
            .into_iter()
            .map(plane::PlaneResult::Map)
            .collect())
    }
    /// True when [`Self::render_tested`] may answer queries on the device: only then is it
    /// worth making them (the default, and the CPU backend, give maps back).
    fn tests_on_device(&self) -> bool {
        false
    }
    /// How many pixels of a plane's map each box test asked of the device should stand for:
    /// a bake asks a plane's tests of the device only while they number at most one per this
    /// many pixels, and takes the map back past that ([`PIXELS_PER_DEVICE_TEST`] unless set).
    fn pixels_per_device_test(&self) -> usize {
        PIXELS_PER_DEVICE_TEST
    }
    /// Keeps `boxes` on the device for the box tests of [`Self::render_tested`]: queries
    /// that name this table ([`plane::PlaneQueries::table`] set to the generation returned)
    /// send a box's index in it ([`plane::PlaneQueries::ids`]) instead of the box. A bake calls
    /// it once, before its cells, with every box its walks name by index; a later call
    /// replaces the table (queries naming an older generation send their boxes whole, with
    /// the same answers). `Ok(None)` where the backend keeps no table: the default, and a
    /// device that tests no boxes or cannot bind that many.
    ///
    /// # Errors
    /// [`BackendError`] when the device fails.
    fn upload_occludee_boxes(&self, _boxes: &[DAabb]) -> Result<Option<u64>, BackendError> {
        Ok(None)
    }
    /// True when [`Self::upload_occluder_parts`] may keep a table: only then does a bake
    /// list the parts' spans for it (on the paper-size forest, 62 MB it would build for
    /// nothing). The default, and the CPU backend: false.
    fn keeps_occluder_parts(&self) -> bool {
        false
    }
    /// Keeps the scene's occluder parts on the device for the projections of
    /// [`Self::render`] and its kin: part `k` is `points[spans[k].0 .. spans[k].1]`. A job
    /// whose [`plane::OccluderSet::table`] is the generation returned then sends, for each
    /// occluder that is a scene part unchanged ([`plane::OccluderSet::parts`]), the part's
    /// index instead of its points. A bake calls it once, before its cells; a later call
    /// replaces the table (jobs naming an older generation send their points, with the same
    /// maps). `Ok(None)` where the backend keeps no table: the default, and a device that
    /// projects no occluder from its points or cannot bind that many. Empty `spans` only
    /// drop the table kept before.
    ///
    /// # Errors
    /// [`BackendError`] when the device fails.
    fn upload_occluder_parts(
        &self,
        _points: &[DVec3],
        _spans: &[(u32, u32)],
    ) -> Result<Option<u64>, BackendError> {
        Ok(None)
    }
    /// [`Self::render_tested`], where `keep[k]` asks to keep job `k`'s map on the device for
    /// later reprojections (an occlusion sweep's plane): the backend then gives back
    /// [`plane::PlaneResult::Kept`] — the answers to its queries (which must be given), the
    /// umbra's bounding box and size, and a stand-in for the map that a later job's
    /// [`plane::Reprojection`] names as its source — or, where it cannot keep it, the map as
    /// [`Self::render_tested`] would. Kept maps are given only to the backend that kept them.
    /// The default keeps nothing.
    ///
    /// # Errors
    /// As [`Self::render`].
    fn render_kept(
        &self,
        jobs: &[plane::PlaneJob],
        queries: &[Option<plane::PlaneQueries>],
        keep: &[bool],
    ) -> Result<Vec<plane::PlaneResult>, BackendError> {
        debug_assert_eq!(jobs.len(), keep.len());
        self.render_tested(jobs, queries)
    }
    /// True when [`Self::render_kept`] may keep maps on the device.
    fn keeps_maps(&self) -> bool {
        false
    }
    /// True when [`Self::rsf_charts`] gives charts on the device rather than the CPU's.
    fn rsf_on_device(&self) -> bool {
        false
    }
    /// Empty ray-space-factorization charts of `cell` ([`RayCharts::new`]'s arguments) on this
    /// backend, for one cell's traversal. The default is the CPU's [`RayCharts`]; the GPU
    /// backend has its own where they were asked for and the device computes in double
    /// precision.
    ///
    /// # Errors
    /// [`BackendError`] when the device fails.
    fn rsf_charts(
        &self,
        cell: &DAabb,
        up: usize,
        resolution: u32,
    ) -> Result<Box<dyn RsfCharts + '_>, BackendError> {
        Ok(Box::new(RayCharts::new(cell, up, resolution)))
    }
    /// The GPU backend itself, for a culler whose GPU twin lives outside this trait (the
    /// shrunk-occluder sampler's hemicube, [`gpu::sampler`]); None on the CPU backend.
    fn as_gpu(&self) -> Option<&gpu::GpuBackend> {
        None
    }
}

/// One occluder for ray space factorization's charts: a convex polygon (points in order,
/// `hull_edges` `None`) or a convex solid (its points and the edges of their hull,
/// [`crate::rsf::hull_edges`]).
#[derive(Clone, Debug)]
pub struct RsfOccluder<'a> {
    /// The polygon's points in order, or the solid's points.
    pub points: Cow<'a, [DVec3]>,
    /// A solid's hull edges (pairs of indices into `points`).
    pub hull_edges: Option<&'a [(usize, usize)]>,
}

/// The raster work of ray space factorization for one cell: its four charts, filled by
/// inserts and read by box tests. Both backends give the same answers: each pixel sees the
/// occluders of a call in their order, exactly as [`RayCharts::insert`] one after the other.
pub trait RsfCharts {
    /// Inserts the occluders, in order ([`RayCharts::insert`] for each).
    ///
    /// # Errors
    /// [`BackendError`] when the device fails.
    fn insert(&mut self, occluders: &[RsfOccluder]) -> Result<(), BackendError>;
    /// Per group of boxes (a range of `boxes`: an object's box, then its pieces), true when
    /// the object is hidden from the cell: its box is, or it has pieces and all of them are
    /// ([`RayCharts::box_hidden`]).
    ///
    /// # Errors
    /// [`BackendError`] when the device fails.
    fn hidden(
        &mut self,
        boxes: &[DAabb],
        groups: &[Range<usize>],
    ) -> Result<Vec<bool>, BackendError>;
    /// What the inserts did so far.
    ///
    /// # Errors
    /// [`BackendError`] when the device fails.
    fn work(&mut self) -> Result<RsfWork, BackendError>;
    /// Every pixel's near and far umbrae, chart by chart (0..4), row by row
    /// ([`RayCharts::umbrae`]'s order): for tests and dumps.
    ///
    /// # Errors
    /// [`BackendError`] when the device fails.
    fn snapshot(&mut self) -> Result<Vec<[Umbra; 2]>, BackendError>;
}

impl RsfCharts for RayCharts {
    fn insert(&mut self, occluders: &[RsfOccluder]) -> Result<(), BackendError> {
        for o in occluders {
            RayCharts::insert(self, &o.points, o.hull_edges);
        }
        Ok(())
    }

    fn hidden(
        &mut self,
        boxes: &[DAabb],
        groups: &[Range<usize>],
    ) -> Result<Vec<bool>, BackendError> {
        Ok(groups
            .iter()
            .map(|r| {
                self.box_hidden(&boxes[r.start]) || {
                    let pieces = &boxes[r.start + 1..r.end];
                    !pieces.is_empty() && pieces.iter().all(|b| self.box_hidden(b))
                }
            })
            .collect())
    }

    fn work(&mut self) -> Result<RsfWork, BackendError> {
        Ok(self.work)
    }

    fn snapshot(&mut self) -> Result<Vec<[Umbra; 2]>, BackendError> {
        let n = self.resolution();
        Ok((0..4)
            .flat_map(|c| (0..n * n).map(move |p| (c, p / n, p % n)))
            .map(|(c, j, i)| self.umbrae(c, j, i))
            .collect())
    }
}
