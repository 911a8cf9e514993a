//! The wgpu backend: occluder extended Projections rasterised on the GPU, with exactly the
//! contract of [`crate::plane`] and at least the conservativeness of the CPU reference
//! ([`cpu`](super::cpu)).
//!
//! # Design: one draw per plane, coverage tested per pixel in the fragment shader
//!
//! Appendix A of Durand et al. 2000 counts the views in the stencil buffer: per occluder, draw
//! its 8 views incrementing the stencil, then draw where the stencil equals 8 writing depth and
//! resetting the stencil. Views of different occluders must never add up, so the stencil must
//! be reset between occluders: at least two draws with different pipelines *per occluder* —
//! 20,000 draws for a 10,000-triangle plane, bound by the CPU's command submission rather than
//! by the GPU — and the "whole pixel inside" rule needs view polygons shrunk by half a pixel
//! whose vertices the rasteriser snaps to its sub-pixel grid (1/256 px on most hardware, 1/16
//! allowed), an error far larger than the 10⁻⁴ px of the CPU reference.
//!
//! Instead every occluder is a few triangles of *one* draw per plane, and the fragment shader
//! decides coverage with edge functions. Per occluder the CPU computes (f64, rayon, before the
//! GPU section) the Projection polygon with the CPU backend's own code (the shared
//! [`coverage`] kernel) — project the points from the 8 cell corners, 8 small hulls, intersect
//! them by clipping, the same quick rejects —
//! and turns each polygon edge, shrunk by the pixel's half-extent along its normal
//! (`½(|nₓ|+|n_y|)`), into an `f32` half-plane with its offset rounded up after adding the
//! CPU's margin and a proven bound on the shader's `f32` error ([`setup`]). The geometry drawn
//! is the polygon itself (clipped to the plane); the fragment shader tests the pixel centre
//! against the occluder's eroded edges and discards unless all pass. "The centre passes every
//! eroded edge of the intersection" is exactly "the closed pixel square lies inside all 8
//! views" (erosion distributes over intersection), per occluder, so views of different
//! occluders never add up, and a rounding can only uncover a pixel, never cover one.
//!
//! Why clip on the CPU rather than send all 8 views' edges and let the GPU intersect them?
//! Measured on planes of 10,000 random triangles at 256² (lavapipe, 2 shared cores): sending
//! the views' edges (minus those no fragment of the drawn geometry can fail) cost 3.9 ms of CPU
//! setup per plane — deciding which of the ~24 edges matter cost more than clipping — with ~15
//! edges and ~380 bytes per occluder, and 58 ms per plane in all; clipping costs 2.9 ms of
//! setup, leaves ~3 edges and ~110 bytes per occluder and a geometry that hugs the covered
//! pixels, and 8 ms per plane in all. On a real GPU, where the fragment work is negligible
//! either way, it still means less CPU time and 3.5× fewer bytes to upload.
//!
//! The Depth Map is an `R32Float` colour target cleared to `+inf` with blend operation `Min`
//! (feature [`wgpu::Features::FLOAT32_BLENDABLE`]): every float Depth, negative or huge, is
//! kept exactly, the minimum over occluders, and `+inf` stays where nothing covers.
//!
//! Slices are filled on the CPU with [`coverage::fill_slices`] as a
//! mask during the setup and merged on read-back (a per-row crossing scan: ~75 µs per plane
//! at 256², cheaper than uploading the segments and running a stencil fill and an erosion pass,
//! and bit-identical to the CPU reference).
//!
//! # Views counted on the GPU ([`GpuProjection::Counting`])
//!
//! The other way to make the Projections, chosen with [`GpuBackend::set_projection`] (CLI
//! `--gpu-projection counting`): the CPU does nothing per occluder beyond its Depth. Occluders
//! of 3–8 points go up as their `f64` points (`prepare::Counted`); a compute pass over every
//! counted occluder of a submission (`shaders/views.wgsl`, needs
//! [`wgpu::Features::SHADER_F64`]) projects them from the cell's 8 corners with the CPU's own
//! expressions, applies the same quick rejects, takes each view's convex hull by gift
//! wrapping (each edge joins two projected points and leaves every point on its left, so the
//! polygon is the hull of some of the points: never larger than the view), erodes every hull
//! edge exactly as `setup.rs` erodes the clipped polygon's (half a pixel along the normal,
//! the shared margin, the `f64` error term, the bound on the fragment shader's `f32` error,
//! offset rounded up), keeps only the edges some pixel centre of the box can fail, and takes
//! the box: the intersection of the views' boxes, clipped to the plane, rounded outward to
//! whole pixels. Then it clips that box of pixel centres by every kept edge in `f64`
//! (Sutherland–Hodgman), loosened by the `f32` bound: the polygon `P` holds every centre the
//! fragment shader can pass. The edges every vertex of `P` passes by twice the `f32` bound
//! (and 10⁻⁶ px for the vertices' rounding) are dropped together: if the box cut by the kept
//! edges held a point outside `P`, the segment from it to `P` would leave `P` across a dropped
//! edge's line at a point of `P` — a convex combination of vertices that all pass that edge by
//! the room — so that region is `P`, and every centre the kept edges pass in `f32` passes the
//! dropped ones in `f32` too: the coverage is unchanged. The box drawn shrinks to the pixels
//! whose centres can lie in `P` (10⁻⁴ px of room); the edges keep the first box's corner as
//! their origin, over which the `f32` bound was proven. An empty `P` (up to rounding) or more
//! vertices than the pass holds keeps the record whole. The record goes out with the box and
//! the kept edges.
//! Then one instanced draw per plane (`vs_counted` in `shaders/projection.wgsl`)
//! draws each record's box as a quad with integer corners — every pixel centre inside gets a
//! fragment on any rasteriser — and the fragment shader counts the pixel in only when its
//! centre passes every edge of all 8 views of that one occluder. Eroding the intersection of
//! the views equals intersecting the eroded views, so this is the contract's rule per
//! occluder, as appendix A's stencil counting is, without a stencil reset between occluders:
//! views of different occluders never add up. Occluders of more points (merged polygons,
//! large solids) are set up on the CPU as before and drawn in the same render pass.
//!
//! A counted occluder that is a scene part unchanged ([`crate::plane::OccluderSet::parts`])
//! sends no points where the bake gave the backend its parts
//! ([`RasterBackend::upload_occluder_parts`], `resident::ResidentParts`): its record's first
//! point is the part's place in that table and its count carries `wave::RESIDENT_POINTS`, and
//! the views pass reads the points there (`occluder_point`), the same `f64`s bit for bit, so
//! the same maps. Each part goes up the first time a wave names it, from the naming
//! occluder's own points (`ResidentTable::given`, `send_given`: a scene's points can be
//! hundreds of megabytes, of which no second copy stays on the CPU), to a table of the parts
//! that fit one storage binding, from the first (`resident::parts_that_fit`; occluders naming
//! the others send their points);
//! [`GpuBackend::set_resident_parts`] sends every occluder's points instead.
//!
//! Same coverage as the clipped path up to near-tie pixels (`tests/gpu.rs`: random triangles,
//! quads and boxes at 16²–256², stretched maps, a cell 10⁵ from the origin, 12-gons mixed in,
//! rejects, sweeps, several submissions, and whole bakes with the same PVS). Measured on
//! lavapipe (2 shared cores, `bake --backend gpu`, shipped scenes, medians of 3 runs, the two
//! projections alternating; the same PVS every time):
//!
//! | scene | projection | CPU setup ms/cell | GPU section ms/cell | GPU passes (timestamps) | ms/cell |
//! | --- | --- | ---: | ---: | ---: | ---: |
//! | `data/demo_forest` (10 cells, 126 planes and 22,763 occluder Projections per cell) | clipped | 155 | 1,036 | 560 | 1,312 |
//! | | counting | 84 | 1,510 | 620 | 1,695 |
//! | | counting, before the views pass clipped the box (all kept edges tested per fragment) | 141 | 2,535 | 1,286 | 2,834 |
//! | `data/demo_city` (24 cells) | clipped | 6.7 | 480 | 81 | 497 |
//! | | counting | 4.8 | 470 | 78 | 517 |
//! | | counting, before the clipping | 7.4 | 717 | 124 | 783 |
//!
//! On a software rasteriser the fragment work dominates. Without the clipping in the views
//! pass, counting tested every view's edges some centre of the box can fail (~8× what the
//! CPU's clipping leaves) over the views' box, and took twice the clipped path's GPU time; with
//! it, the fragments test about as many edges over about as many pixels as the clipped path,
//! and the views pass takes 5–11 ms of the demo forest's ~620 ms of GPU passes per cell
//! (22,663 counted occluders; timestamps, [`RenderStats::views_time`]; 4–5 ms before the
//! clipping; one run, the first after a build, measured 320 ms of views per cell, and no run
//! since). With counting the forest's GPU section still runs ~890 ms per cell beyond its timed
//! passes, against ~480 ms with clipping, and `perf` counts 67 % more samples in lavapipe's
//! rasteriser threads: not yet explained. Drawing an octagon hugging `P` instead of its box
//! (18 vertices per instance) measured no gain (medians of 3 interleaved runs: 1,262 against
//! 1,161 ms per cell), so the box stays. On a real GPU, where fragment and compute work cost
//! little and the CPU setup bounds a cell, counting takes the per-occluder clipping off the
//! CPU. [`GpuProjection::Clipped`] stays the default
//! until it is measured on a real GPU (`umbrasweep bench --backend gpu --gpu-projection
//! counting`).
//!
//! # Reprojection (occlusion sweep)
//!
//! A job carries any number of [`Reprojection`]s (the bake's skip list: the previous plane and
//! planes 2, 4, 8… back, each with its own source Depth Map, windows and Depth). Each one that
//! can set a pixel is one fullscreen-triangle draw inside the plane's own render pass, after
//! the occluders, with the same `Min` blending (`shaders/reproject.wgsl`): a pixel any of them
//! sets ends with the least of their Depths, exactly as the CPU applies them one after the
//! other with [`Reprojection::apply`].
//!
//! The filter is [`Reprojection::mask`]'s window test — pixel `(i, j)` is set when every source
//! pixel of the box `cols[i] × rows[j]` is in the umbra — evaluated with a summed-area table.
//! During the setup (parallel) the CPU builds per *source* the table of
//! its pixels *outside* the umbra (entry `(x, y)` counts those in `[0, x] × [0, y]`, with
//! the CPU's `d <= 0` test, so NaNs are outside), one pass over the source it had to read
//! anyway; the table is uploaded with `queue.write_texture` into an `R32Uint` texture that
//! stays on the device while the source lives (`tables.rs`: keyed by the source's `Arc`, so
//! the next plane's and the skip list's later reprojections of the same map take it from
//! there), and the windows, after a 16-byte header (the Depth, the resolution, `+inf`), into a shared
//! storage buffer. The fragment shader reads the box's count with four integer loads and writes
//! the Depth where it is zero and `+inf` (a no-op under `Min`) elsewhere. Everything is integer,
//! so reprojected pixels are bit-identical to the CPU's. Each draw is scissored to the bounding
//! box of the pixels whose box lies inside the umbra's bounding box — no other pixel can be
//! set. A reprojection that cannot set a pixel (no umbra in its source, no valid window along an
//! axis, or no window inside the umbra's bounding box) is dropped during the setup — the same
//! result — and a plane with a reprojection but no occluder still goes to the GPU.
//!
//! Why a table rather than the separable filter in two passes (per reprojection, a horizontal
//! pass into an `R8Unorm` intermediate looping over the column windows, then a vertical draw
//! looping over the row windows)? Measured on 6 planes at 256² with 60 occluders each and 1 to
//! 7 reprojections (windows 56 px wide on average; lavapipe, 2 shared cores, GPU section from
//! [`RenderStats`]): the two passes cost 2.5 ms of GPU time per extra reprojection of a plane
//! (7 ms with sources entirely in the umbra, where no loop exits early, even scissored as
//! above), the table 0.26–0.55 ms (0.65–1.1 ms; best of 10, over several runs on the shared
//! machine), for ~45 µs of CPU per table; no intermediate texture, and no extra render pass.
//! Each table takes `w × h × 4` bytes of device memory for a `w × h` source while the source
//! lives (the bake keeps `O(log planes)` per direction of a cell in flight); evicted tables'
//! textures are reused.
//!
//! Keeping the tables: on `data/demo_forest` (10 cells, sweep; `bake --backend gpu`,
//! lavapipe, medians of 3 runs, alternating builds) a plane carries several reprojections but
//! only one new source, so uploads per cell fell from 76,961 KB to 31,265 KB, the CPU setup
//! from 249 ms to 228 ms, the GPU section from 1,263 ms to 1,223 ms and the cell from
//! 1,772 ms to 1,629 ms.
//!
//! Keeping the maps ([`RasterBackend::render_kept`], on unless
//! [`GpuBackend::set_keep_sweep_maps`]`(false)` or tests on the CPU): a sweep plane whose
//! occludee tests the device answers (`hdm.rs`) is also kept as a reprojection source. The
//! occludee test pass builds its table from the merged map in the pyramid buffer (one
//! invocation per row, then per column; integer counts, so the CPU's table exactly), copies it
//! into a table texture and reads back only the umbra's bounding box and the count outside it;
//! the texture is cached for a stand-in of the map ([`DepthMap::on_device`]), which the bake
//! names as the source of its later reprojections. No map and no table crosses the bus.
//!
//! # Per `render` call
//!
//! All jobs (a cell's 6–30 planes) are prepared in parallel, uploaded into shared, grown-only
//! vertex/data/uniform buffers, encoded in one command buffer — per plane one render pass, one
//! draw per chunk of the data buffer (one chunk unless the plane's data exceed the device's
//! storage binding size) and per reprojection, one texture-to-buffer copy — and submitted once;
//! then all staging buffers are mapped at once and the device is polled with a timeout. Render
//! targets and staging buffers are pooled per map size (`width × height`:
//! sweep planes' maps are stretched, and a reprojection's source may differ from its target). Planes no
//! occluder can cover and no reprojection can set skip the GPU. Jobs are split into several
//! submissions only to bound memory (256 MiB of targets, read-back buffers and new tables,
//! 512 MiB of data). Each call takes a resource pool of its own (the backend keeps one per call in
//! flight), so cells baked on several threads prepare, upload, render and read back their
//! planes at the same time, without a lock around the device section.
//!
//! Per `w × h` plane: 1 render pass, 1 draw (≈ 1.2 triangles per occluder drawn), `w × h × 4`
//! bytes read back (rows padded to 256 bytes, i.e. `256 × h` bytes when `w < 64`). Each
//! reprojection from a `sw × sh` source adds 1 draw and `8·(w + h + 3)` bytes uploaded, and
//! the first of a source `sw × sh × 4` bytes more (its table) and as much texture to the
//! submission's memory budget. See
//! [`GpuBackend::last_stats`]. Where the device has [`wgpu::Features::TIMESTAMP_QUERY`]
//! (the backend's own device takes it whenever the adapter has it), each render pass also
//! writes GPU timestamps at its start and end, resolved and read back with the maps
//! ([`RenderStats::pass_time`]); `umbrasweep bench` prints them per cell with the bytes up and
//! down.
//!
//! # Ray space factorization
//!
//! [`RasterBackend::rsf_charts`] gives a cell's charts on the device (`rsf.rs`,
//! `shaders/rsf.wgsl`: compute passes in `f64`, one submission per traversal wave, a flag per
//! box read back) where it has [`wgpu::Features::SHADER_F64`], which the backend's own device
//! takes whenever the adapter has it; they are the CPU's charts pixel for pixel. Its passes,
//! bytes, wall time and (with timestamps) compute-pass times are added to
//! [`GpuBackend::total_stats`].
//!
//! # Device and work apart
//!
//! As in wgpu's `hello_compute` example, creating the device is apart from the work done with
//! it. [`GpuBackend::new`] finds the best adapter, creates the backend's own device (every
//! limit the adapter has, [`GpuBackend::REQUIRED_FEATURES`]) and installs a device-lost
//! callback and an uncaptured-error handler on it; [`GpuBackend::with_device`] takes an
//! engine's device and queue instead and installs neither (they are the engine's). Both check
//! the device's features and limits and create the two pipelines and their bind group layouts
//! once (`pipelines.rs`), with empty resource pools. A [`render`](RasterBackend::render) call
//! then prepares its jobs on the CPU (`prepare.rs`) and runs them on the GPU in waves
//! (`wave.rs`: layout, allocate, upload, encode, submit, wait, read back).
//!
//! Device loss, out-of-memory and validation errors become [`BackendError`]s
//! ([`BackendError::DeviceLost`], [`BackendError::OutOfMemory`], [`BackendError::Validation`],
//! …; [`BackendError::device_failed`] is true for all of them): errors of
//! the backend's work are caught by error scopes (on its own device, also by the
//! uncaptured-error handler), loss by the device-lost callback (on an engine's device, by the
//! failing submission, poll or read-back), and waits poll with a timeout, so a failing device
//! never hangs a bake.
//!
//! [`coverage`]: crate::backend::coverage
//! [`coverage::fill_slices`]: crate::backend::coverage::fill_slices
//! [`Reprojection`]: crate::plane::Reprojection
//! [`Reprojection::apply`]: crate::plane::Reprojection::apply
//! [`Reprojection::mask`]: crate::plane::Reprojection::mask

mod device;
mod hdm;
mod pipelines;
mod prepare;
mod resident;
mod rsf;
pub mod sampler;
pub mod setup;
mod tables;
mod wave;

pub use device::hardware_adapter_available;

use super::{BackendError, RasterBackend};
use crate::plane::{DepthMap, PlaneJob, PlaneQueries, PlaneResult};
use device::{DeviceLimits, Failure};
use pipelines::Pipelines;
use prepare::{Prepared, merge_mask, prepare};
use rayon::prelude::*;
use std::sync::Mutex;
use std::time::{Duration, Instant};
use wave::{Pool, plan_waves};

/// The WGSL source of every pass, `(file name, source)`, for validation in tests: the `f64`
/// passes (`rsf.wgsl`, `views.wgsl`) with `shaders/rounding.wgsl` prepended, and that file alone.
pub const SHADERS: &[(&str, &str)] = &[
    (
        "shaders/projection.wgsl",
        include_str!("../../../shaders/projection.wgsl"),
    ),
    (
        "shaders/reproject.wgsl",
        include_str!("../../../shaders/reproject.wgsl"),
    ),
    (
        "shaders/rsf.wgsl",
        concat!(
            include_str!("../../../shaders/rounding.wgsl"),
            include_str!("../../../shaders/rsf.wgsl")
        ),
    ),
    (
        "shaders/views.wgsl",
        concat!(
            include_str!("../../../shaders/rounding.wgsl"),
            include_str!("../../../shaders/views.wgsl")
        ),
    ),
    (
        "shaders/rounding.wgsl",
        include_str!("../../../shaders/rounding.wgsl"),
    ),
    (
        "shaders/sampler.wgsl",
        concat!(
            include_str!("../../../shaders/rounding.wgsl"),
            include_str!("../../../shaders/sampler_views.wgsl"),
            include_str!("../../../shaders/sampler.wgsl"),
            include_str!("../../../shaders/sampler_blend.wgsl")
        ),
    ),
    (
        "shaders/sampler_setup.wgsl",
        concat!(
            include_str!("../../../shaders/rounding.wgsl"),
            include_str!("../../../shaders/sampler_views.wgsl"),
            include_str!("../../../shaders/sampler_setup.wgsl")
        ),
    ),
    (
        "shaders/sampler_views.wgsl",
        include_str!("../../../shaders/sampler_views.wgsl"),
    ),
    (
        "shaders/sampler_fill.wgsl",
        concat!(
            include_str!("../../../shaders/rounding.wgsl"),
            include_str!("../../../shaders/sampler_views.wgsl"),
            include_str!("../../../shaders/sampler.wgsl"),
            include_str!("../../../shaders/sampler_fill.wgsl")
        ),
    ),
    (
        "shaders/hdm.wgsl",
        concat!(
            include_str!("../../../shaders/coverage.wgsl"),
            include_str!("../../../shaders/hdm.wgsl")
        ),
    ),
    (
        "shaders/boxes.wgsl",
        concat!(
            include_str!("../../../shaders/rounding.wgsl"),
            include_str!("../../../shaders/coverage.wgsl"),
            include_str!("../../../shaders/boxes.wgsl")
        ),
    ),
    // The render fill's depths, validated within `shaders/sampler.wgsl` (this is that module).
    (
        "shaders/sampler_blend.wgsl",
        concat!(
            include_str!("../../../shaders/rounding.wgsl"),
            include_str!("../../../shaders/sampler_views.wgsl"),
            include_str!("../../../shaders/sampler.wgsl"),
            include_str!("../../../shaders/sampler_blend.wgsl")
        ),
    ),
    // The answers' codes, prepended to `hdm.wgsl` and `boxes.wgsl`.
    (
        "shaders/coverage.wgsl",
        include_str!("../../../shaders/coverage.wgsl"),
    ),
];

const PROJECTION_WGSL: &str = SHADERS[0].1;
const REPROJECT_WGSL: &str = SHADERS[1].1;
const RSF_WGSL: &str = SHADERS[2].1;
const VIEWS_WGSL: &str = SHADERS[3].1;
const SAMPLER_WGSL: &str = SHADERS[5].1;
const BOXES_WGSL: &str = SHADERS[10].1;
const SAMPLER_SETUP_WGSL: &str = SHADERS[6].1;
const SAMPLER_FILL_WGSL: &str = SHADERS[8].1;
const HDM_WGSL: &str = SHADERS[9].1;

/// How the GPU backend gets each occluder's Projection (its 8 views intersected), the pixels
/// it covers. Both keep the contract of [`crate::plane`] with the same coverage up to
/// pixels within a rounding error of a view's edge (tests: `tests/gpu.rs`).
///
/// ```
/// use umbrasweep::backend::gpu::GpuProjection;
/// assert_eq!("counting".parse::<GpuProjection>(), Ok(GpuProjection::Counting));
/// // (A `GpuBackend` picks its own default: `GpuBackend::set_projection`.)
/// assert_eq!(GpuProjection::default(), GpuProjection::Clipped);
/// assert!("stencil".parse::<GpuProjection>().is_err());
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum GpuProjection {
    /// The CPU intersects the 8 views of every occluder in `f64` (the CPU backend's own
    /// kernel), erodes the polygon's edges and uploads them; the GPU tests pixel centres
    /// against those few edges (`shaders/projection.wgsl`). The default on software adapters
    /// and devices without [`wgpu::Features::SHADER_F64`].
    #[default]
    Clipped,
    /// The occluders' points go up as they are; a compute pass projects every occluder's views
    /// from the 8 corners in `f64`, takes their hulls and erodes their edges
    /// (`shaders/views.wgsl`), and one instanced draw per plane counts them per fragment: a
    /// pixel is covered when its centre passes every eroded edge of all 8 views of one
    /// occluder (`vs_counted` in `shaders/projection.wgsl`). Occluders of more than 8 points are set up on the
    /// CPU as with [`Clipped`](Self::Clipped). Needs [`wgpu::Features::SHADER_F64`]; the
    /// default on hardware adapters that have it.
    Counting,
}

impl std::str::FromStr for GpuProjection {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "clipped" => Ok(GpuProjection::Clipped),
            "counting" => Ok(GpuProjection::Counting),
            _ => Err(format!(
                "unknown GPU projection `{s}`: use `clipped` (views intersected on the CPU) or \
                 `counting` (views projected and counted on the GPU)"
            )),
        }
    }
}

impl std::fmt::Display for GpuProjection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            GpuProjection::Clipped => "clipped",
            GpuProjection::Counting => "counting",
        })
    }
}

/// Stride of per-plane uniforms (WebGPU's maximum `min_uniform_buffer_offset_alignment`).
const UNIFORM_STRIDE: u64 = 256;

/// The wgpu backend. Device, pipelines and pools are created once, by [`GpuBackend::new`] or
/// [`GpuBackend::with_device`]; every [`render`](RasterBackend::render) call reuses them.
pub struct GpuBackend {
    adapter_name: String,
    device: wgpu::Device,
    queue: wgpu::Queue,
    pipelines: Pipelines,
    /// First device-lost or uncaptured error message; once set, every call fails. Only the
    /// backend's own device ([`GpuBackend::new`]) reports into it.
    failure: Failure,
    limits: DeviceLimits,
    /// Resource pools, one per `render` call in flight: a call takes one (or a new one) and
    /// gives it back, so cells baked on several threads overlap on the device.
    pools: Mutex<Vec<Pool>>,
    /// Nanoseconds per timestamp tick, when the device has
    /// [`wgpu::Features::TIMESTAMP_QUERY`]: each render pass is then timed on the GPU.
    timestamp_period: Option<f64>,
    stats: Mutex<RenderStats>,
    /// Sums over every call since creation.
    totals: Mutex<RenderStats>,
    /// Ray space factorization's pipelines, where the device has `SHADER_F64`.
    rsf_pipelines: Option<rsf::RsfPipelines>,
    /// Ray space factorization's charts asked on the device ([`GpuBackend::set_rsf_on_gpu`]).
    rsf_wanted: bool,
    /// Device memory the shrunk-occluder sampler's GPU samplers of a bake may take together
    /// ([`GpuBackend::set_sampler_memory`]).
    sampler_memory: u64,
    /// Submissions and polls one thread at a time, each poll blocking until its submission is
    /// done ([`GpuBackend::set_serial_polls`]); held around each of them when set.
    serial_polls: Option<Mutex<()>>,
    /// Ray space factorization's buffers, one set per cell in flight.
    rsf_pool: Mutex<Vec<rsf::RsfBuffers>>,
    /// The views pass and counted draw, where the device has `SHADER_F64`.
    view_pipelines: Option<pipelines::ViewPipelines>,
    /// The pyramid and occludee tests of the planes whose tests the device answers.
    hdm_pipelines: hdm::HdmPipelines,
    /// Box tests' rectangles and answers (`shaders/boxes.wgsl`), where the device has
    /// `SHADER_F64`: without them the device answers rectangle tests alone, and
    /// [`RasterBackend::tests_on_device`] is false (the bake asks box tests).
    box_pipelines: Option<hdm::BoxPipelines>,
    /// Occludee tests answered on the device ([`GpuBackend::set_tests_on_device`]).
    tests_wanted: bool,
    /// Keep sweeps' maps on the device ([`GpuBackend::set_keep_sweep_maps`]).
    keep_wanted: bool,
    /// Pixels per box test asked of the device ([`GpuBackend::set_pixels_per_device_test`]).
    pixels_per_test: usize,
    /// How occluders' Projections are made ([`GpuBackend::set_projection`]).
    projection: GpuProjection,
    /// Reprojection sources' summed-area tables kept on the device across calls.
    tables: tables::TableCache,
    /// Keep a bake's occludee boxes on the device ([`GpuBackend::set_resident_boxes`]).
    resident_wanted: bool,
    /// The last [`RasterBackend::upload_occludee_boxes`]'s table, and the generations given.
    resident: Mutex<Option<hdm::ResidentBoxes>>,
    generations: std::sync::atomic::AtomicU64,
    /// Keep a bake's occluder parts on the device ([`GpuBackend::set_resident_parts`]).
    parts_wanted: bool,
    /// The last [`RasterBackend::upload_occluder_parts`]'s table.
    resident_parts: Mutex<Option<resident::ResidentParts>>,
}

impl std::fmt::Debug for GpuBackend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuBackend")
            .field("adapter", &self.adapter_name)
            .finish_non_exhaustive()
    }
}

/// What the last [`render`](RasterBackend::render) call did, for reports and benchmarks.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RenderStats {
    /// Planes in the call.
    pub planes: usize,
    /// Planes sent to the GPU (the others had no occluder that can cover a pixel and no
    /// reprojection that can set one).
    pub gpu_planes: usize,
    /// Reprojections run on the GPU (each one draw in its plane's pass); those that cannot set
    /// a pixel are dropped and not counted.
    pub reprojections: usize,
    /// Queue submissions (one unless memory budgets split the call).
    pub submissions: usize,
    /// Render passes (one per GPU plane).
    pub passes: usize,
    /// Draw calls (one per GPU plane with occluders unless its data exceed one storage
    /// binding, plus one per reprojection).
    pub draws: usize,
    /// Occluders drawn (after the quick rejects), their triangles and their eroded edges.
    pub occluders: usize,
    /// Triangles of the occluders drawn.
    pub triangles: usize,
    /// Eroded edges drawn (conservative rasterisation of the occluders' outlines).
    pub edges: usize,
    /// Reprojection tables built and uploaded by the call, and those taken from the device
    /// (built by an earlier reprojection of the same source).
    pub tables_uploaded: usize,
    /// See `tables_uploaded`.
    pub tables_reused: usize,
    /// Sweep planes whose maps stayed on the device ([`RasterBackend::render_kept`]), their
    /// tables built there.
    pub kept_maps: usize,
    /// Occluders whose views the GPU computed ([`GpuProjection::Counting`]); they are not in
    /// `occluders`, `triangles` or `edges` (those are known on the GPU only).
    pub counted: usize,
    /// Of `counted`, those that named a scene part kept on the device
    /// ([`RasterBackend::upload_occluder_parts`]) instead of sending their points.
    pub counted_resident: usize,
    /// Bytes written to GPU buffers and textures (vertices, records and edges, uniforms,
    /// reprojection windows and summed-area tables).
    pub bytes_uploaded: u64,
    /// Bytes copied back from the GPU (padded rows included).
    pub bytes_read_back: u64,
    /// Depth Maps copied back from the GPU (the rest of `bytes_read_back` is answers,
    /// summaries and timestamps).
    pub maps_read_back: usize,
    /// Wall time of the CPU setup (parallel), of the GPU section (upload to read-back), total.
    pub setup: Duration,
    /// Wall time of the GPU section, from the first upload to the last read-back.
    pub gpu: Duration,
    /// Wall time of the whole render, setup included.
    pub total: Duration,
    /// GPU time of the timed passes — every render pass, and the views pass of
    /// [`GpuProjection::Counting`] — from the GPU's own timestamps at the start and end of each
    /// pass (zero without [`wgpu::Features::TIMESTAMP_QUERY`]).
    pub pass_time: Duration,
    /// The part of `pass_time` spent in the views passes ([`GpuProjection::Counting`]).
    pub views_time: Duration,
    /// Render passes timed with timestamps (0 when the device has none).
    pub timed_passes: usize,
}

impl RenderStats {
    /// Adds another call's counters and timings.
    pub fn add(&mut self, o: &RenderStats) {
        self.planes += o.planes;
        self.gpu_planes += o.gpu_planes;
        self.reprojections += o.reprojections;
        self.submissions += o.submissions;
        self.passes += o.passes;
        self.draws += o.draws;
        self.occluders += o.occluders;
        self.triangles += o.triangles;
        self.edges += o.edges;
        self.counted += o.counted;
        self.counted_resident += o.counted_resident;
        self.tables_uploaded += o.tables_uploaded;
        self.tables_reused += o.tables_reused;
        self.kept_maps += o.kept_maps;
        self.maps_read_back += o.maps_read_back;
        self.bytes_uploaded += o.bytes_uploaded;
        self.bytes_read_back += o.bytes_read_back;
        self.setup += o.setup;
        self.gpu += o.gpu;
        self.total += o.total;
        self.pass_time += o.pass_time;
        self.views_time += o.views_time;
        self.timed_passes += o.timed_passes;
    }
}

impl GpuBackend {
    /// The features a device needs for this backend: `R32Float` render targets with blending
    /// ([`wgpu::Features::FLOAT32_BLENDABLE`], the Depth Map's `Min` blend).
    pub const REQUIRED_FEATURES: wgpu::Features = device::REQUIRED_FEATURES;

    /// Creates the instance, picks the best adapter (hardware before software), creates the
    /// backend's own device — [`Self::REQUIRED_FEATURES`] and every limit the adapter has,
    /// with a device-lost callback and an uncaptured-error handler — and then the backend on
    /// it as [`Self::with_device`] does.
    ///
    /// `WGPU_BACKEND` (e.g. `vulkan`) restricts the backends searched.
    ///
    /// # Errors
    /// [`BackendError::NoAdapter`] when no adapter exists or none supports `float32-blendable`
    /// render targets; [`BackendError::CreateDevice`] when the device cannot be created; as
    /// [`Self::with_device`] otherwise.
    pub fn new() -> Result<Self, BackendError> {
        let adapter = device::best_adapter()?;
        let (device, queue) = device::request_device(&adapter)?;
        let failure = device::install_failure_handlers(&device);
        Self::on_device(device, queue, adapter.get_info().name, failure)
    }

    /// The backend on an existing device and queue, e.g. an engine's: checks what the device
    /// supports, creates the pipelines and bind group layouts (every object labelled) and
    /// empty resource pools. The results are the same as with [`Self::new`] on the same
    /// adapter.
    ///
    /// The device must have been created with:
    /// * the features [`Self::REQUIRED_FEATURES`] (`FLOAT32_BLENDABLE`);
    /// * limits at least WebGPU's defaults ([`wgpu::Limits::default`]); the backend adapts
    ///   to larger ones. A plane's Depth Map (and a reprojection's source) is at most
    ///   `max_texture_dimension_2d` (and 32768) pixels per side; one draw's occluder data is
    ///   at most `max_storage_buffer_binding_size` (more makes more draws); uploads and
    ///   submissions stay within `max_buffer_size`. [`Self::new`] requests every limit the
    ///   adapter has;
    /// * storage buffers readable in vertex shaders (every Vulkan, Metal and DX12 device).
    ///
    /// The backend installs no device-lost callback and no uncaptured-error handler on it:
    /// those stay the engine's. Its own work runs inside error scopes, so its errors come
    /// back as [`BackendError`]s and never reach the engine's handler; a lost device fails
    /// the backend's next submission, poll or read-back. The backend's buffers and textures
    /// live as long as it does. The device may serve other work meanwhile; a `render` call
    /// polls it (`Device::poll`, never blocking) while it waits, which also runs the engine's
    /// callbacks. An engine thread that waits on the same device with a timeout
    /// (`PollType::Wait` with `timeout: Some(..)`) while the backend works may trip wgpu-core
    /// 30's queue-empty assertion (gfx-rs/wgpu#9958) when its wait times out; use
    /// `PollType::Poll`, or waits without a timeout.
    ///
    /// # Errors
    /// [`BackendError::MissingFeatures`], [`BackendError::LimitTooLow`] or
    /// [`BackendError::UniformAlignment`] when the device lacks a required feature or a limit
    /// the pipelines need (the message names it and says what to request when creating the
    /// device); [`BackendError::Validation`] or [`BackendError::OutOfMemory`] when it reports
    /// an error while the pipelines are created.
    ///
    /// # Example
    ///
    /// ```no_run
    /// use umbrasweep::backend::RasterBackend;
    /// use umbrasweep::backend::gpu::GpuBackend;
    ///
    /// # fn main() -> Result<(), Box<dyn std::error::Error>> {
    /// // The engine's device, created with the backend's features.
    /// let instance = wgpu::Instance::default();
    /// let adapter =
    ///     pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))?;
    /// let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
    ///     label: Some("engine device"),
    ///     required_features: GpuBackend::REQUIRED_FEATURES,
    ///     required_limits: wgpu::Limits::default(),
    ///     ..Default::default()
    /// }))?;
    /// // The backend shares it (wgpu devices and queues are cheap handles to clone).
    /// let backend = GpuBackend::with_device(device.clone(), queue.clone())?;
    /// let maps = backend.render(&[])?;
    /// assert!(maps.is_empty());
    /// # Ok(())
    /// # }
    /// ```
    pub fn with_device(device: wgpu::Device, queue: wgpu::Queue) -> Result<Self, BackendError> {
        let adapter_name = device.adapter_info().name;
        Self::on_device(device, queue, adapter_name, Failure::default())
    }

    /// The shared constructor: the device's limits checked, the pipelines, empty pools.
    fn on_device(
        device: wgpu::Device,
        queue: wgpu::Queue,
        adapter_name: String,
        failure: Failure,
    ) -> Result<Self, BackendError> {
        let limits = DeviceLimits::check(device.features(), &device.limits())?;
        let pipelines = Pipelines::new(&device)?;
        let scope = device::ErrorScopes::push(&device);
        let hdm_pipelines = hdm::HdmPipelines::new(&device);
        scope.check()?;
        let timestamp_period = device
            .features()
            .contains(wgpu::Features::TIMESTAMP_QUERY)
            .then(|| f64::from(queue.get_timestamp_period()));
        let f64_ok = device.features().contains(wgpu::Features::SHADER_F64);
        let rsf_pipelines = if f64_ok {
            Some(rsf::RsfPipelines::new(&device)?)
        } else {
            None
        };
        let view_pipelines = if f64_ok {
            Some(pipelines::ViewPipelines::new(&device)?)
        } else {
            None
        };
        // (WebGPU's default limits allow 8 storage buffers a stage; the box tests bind 9.)
        let box_pipelines = if f64_ok
            && device.limits().max_storage_buffers_per_shader_stage >= hdm::BOX_STORAGE_BUFFERS
        {
            let scope = device::ErrorScopes::push(&device);
            let p = hdm::BoxPipelines::new(&device, BOXES_WGSL);
            scope.check()?;
            Some(p)
        } else {
            None
        };
        // The issue's rule (#18): counting is the default where it is not slower — on the
        // NVIDIA H200 measured (README) — and clipped on software adapters, where counting's
        // compute pass runs on the CPU and was slower (lavapipe).
        let hardware = device.adapter_info().device_type != wgpu::DeviceType::Cpu;
        let projection = if hardware && view_pipelines.is_some() {
            GpuProjection::Counting
        } else {
            GpuProjection::Clipped
        };
        Ok(GpuBackend {
            adapter_name,
            device,
            queue,
            pipelines,
            failure,
            limits,
            pools: Mutex::default(),
            timestamp_period,
            stats: Mutex::default(),
            totals: Mutex::default(),
            rsf_pipelines,
            rsf_wanted: false,
            serial_polls: None,
            sampler_memory: sampler::DEFAULT_SAMPLER_MEMORY,
            rsf_pool: Mutex::default(),
            view_pipelines,
            hdm_pipelines,
            box_pipelines,
            tests_wanted: true,
            keep_wanted: true,
            pixels_per_test: crate::backend::PIXELS_PER_DEVICE_TEST,
            projection,
            tables: tables::TableCache::default(),
            resident_wanted: true,
            resident: Mutex::default(),
            generations: std::sync::atomic::AtomicU64::new(0),
            parts_wanted: true,
            resident_parts: Mutex::default(),
        })
    }

    /// Chooses how occluders' Projections are made. The default is the backend's own choice:
    /// [`GpuProjection::Counting`] on a hardware adapter with
    /// [`wgpu::Features::SHADER_F64`], [`GpuProjection::Clipped`] on a software one (such as
    /// lavapipe) or without `SHADER_F64`. Both give the same PVS.
    ///
    /// # Errors
    /// [`BackendError::MissingFeatures`] for [`GpuProjection::Counting`] on a device without
    /// [`wgpu::Features::SHADER_F64`] (the backend's own device takes it whenever the adapter
    /// has it); the backend keeps its projection.
    pub fn set_projection(&mut self, projection: GpuProjection) -> Result<(), BackendError> {
        if projection == GpuProjection::Counting && self.view_pipelines.is_none() {
            return Err(BackendError::MissingFeatures {
                missing: wgpu::Features::SHADER_F64,
            });
        }
        self.projection = projection;
        Ok(())
    }

    /// Submits and polls one thread at a time, each poll blocking until the device has done
    /// the submission waited for (`on`: how every GPU path waited before December 2026), or
    /// lets every thread submit and poll at once (the default). Both give the same results;
    /// the serial way leaves the device idle between one thread's submission and the next,
    /// and is kept to measure that (`--example gpu_threads`).
    pub fn set_serial_polls(&mut self, on: bool) {
        self.serial_polls = on.then(Mutex::default);
    }

    /// Runs ray space factorization's charts on the device (`on`), or the CPU's charts (the
    /// default: measured faster on every device so far, since each wave of a cell's traversal
    /// is a submission waited for: on an NVIDIA H200, 328 ms per city cell on the device against
    /// 84 ms on the same machine's CPU, 402 against 56 for Munich, measured while a bake's
    /// threads submitted one at a time, [`GpuBackend::set_serial_polls`]; on lavapipe 729
    /// against 58). Both give the same charts (`tests/gpu.rs`).
    ///
    /// # Errors
    /// [`BackendError::MissingFeatures`] for `on` on a device without
    /// [`wgpu::Features::SHADER_F64`]; the backend keeps the CPU's charts.
    pub fn set_rsf_on_gpu(&mut self, on: bool) -> Result<(), BackendError> {
        if on && self.rsf_pipelines.is_none() {
            return Err(BackendError::MissingFeatures {
                missing: wgpu::Features::SHADER_F64,
            });
        }
        self.rsf_wanted = on;
        Ok(())
    }

    /// Answers occludee tests on the device where the bake records them (`on`, the default:
    /// the maps stay there and only the answers come back, [`RasterBackend::render_tested`];
    /// sweep planes' maps too unless [`GpuBackend::set_keep_sweep_maps`]`(false)`) or reads
    /// every map back for the CPU's pyramid (for comparisons). The same PVS either way.
    pub fn set_tests_on_device(&mut self, on: bool) {
        self.tests_wanted = on;
    }

    /// How many pixels of a plane's map each occludee test asked of the device should stand
    /// for ([`RasterBackend::pixels_per_device_test`]; default
    /// [`crate::backend::PIXELS_PER_DEVICE_TEST`], at least 1): fewer asks the device more
    /// planes' tests and reads fewer maps back, for more of the CPU's recording. The same PVS
    /// at any value.
    pub fn set_pixels_per_device_test(&mut self, pixels: usize) {
        self.pixels_per_test = pixels.max(1);
    }

    /// Keeps a bake's occludee boxes on the device (`on`, the default: box tests then send
    /// indices, 4 bytes a test instead of 56, [`RasterBackend::upload_occludee_boxes`]) or
    /// sends every box with its test (for comparisons). The same PVS either way.
    pub fn set_resident_boxes(&mut self, on: bool) {
        self.resident_wanted = on;
        if !on {
            *self.resident.lock().unwrap_or_else(|e| e.into_inner()) = None;
        }
    }

    /// The occludee boxes kept on the device, where a bake gave them.
    fn resident_boxes(&self) -> Option<hdm::ResidentBoxes> {
        self.resident
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    /// Keeps a bake's occluder parts on the device for the counted projections (`on`, the
    /// default: a counted occluder that is a scene part unchanged then sends its 16-byte
    /// record and no points, [`RasterBackend::upload_occluder_parts`]) or sends every
    /// occluder's points (for comparisons). The same maps either way; it matters only with
    /// [`GpuProjection::Counting`].
    pub fn set_resident_parts(&mut self, on: bool) {
        self.parts_wanted = on;
        if !on {
            *self
                .resident_parts
                .lock()
                .unwrap_or_else(|e| e.into_inner()) = None;
        }
    }

    /// The occluder parts kept on the device, where a bake gave them.
    fn resident_parts(&self) -> Option<resident::ResidentParts> {
        self.resident_parts
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    /// A new table generation (never 0).
    fn next_generation(&self) -> u64 {
        self.generations
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed)
            + 1
    }

    /// Keeps occlusion sweeps' maps on the device (`on`, the default, with the tests there
    /// too: [`RasterBackend::render_kept`]) or reads them back for the CPU (for comparisons).
    /// The same PVS either way.
    pub fn set_keep_sweep_maps(&mut self, on: bool) {
        self.keep_wanted = on;
    }

    /// Lets the shrunk-occluder sampler's GPU samplers of one bake take up to `bytes` of
    /// device memory together (default [`sampler::DEFAULT_SAMPLER_MEMORY`], 4 GiB; CLI
    /// `--gpu-sampler-memory`). Each sampler serves one thread's renders (about 0.7 GB at 512
    /// pixels on the fine forest, 1.8 GB at 1,024: [`sampler::GpuSampler::device_bytes`]); a
    /// level makes its first whatever the budget and more only while they fit, and its other
    /// lanes wait for one. wgpu cannot tell how much memory a device has, so the default suits
    /// a consumer GPU; on a large one more samplers keep more of a bake's threads rendering.
    /// The PVS is the same whatever the budget.
    pub fn set_sampler_memory(&mut self, bytes: u64) {
        self.sampler_memory = bytes;
    }

    /// Device memory the sampler's GPU samplers may take together
    /// ([`GpuBackend::set_sampler_memory`]).
    pub fn sampler_memory(&self) -> u64 {
        self.sampler_memory
    }

    /// How occluders' Projections are made ([`GpuBackend::set_projection`]).
    pub fn projection(&self) -> GpuProjection {
        self.projection
    }

    /// The adapter's information (name, backend, device type, driver).
    pub fn adapter_info(&self) -> wgpu::AdapterInfo {
        self.device.adapter_info()
    }

    /// Destroys the device, as a driver reset would lose it: every later call fails with
    /// [`BackendError::DeviceLost`]. For tests of the failure path.
    #[doc(hidden)]
    pub fn simulate_device_loss(&self) {
        self.device.destroy();
    }

    /// True when the device has [`wgpu::Features::TIMESTAMP_QUERY`]: every render pass is
    /// then timed on the GPU ([`RenderStats::pass_time`]). The backend's own device
    /// ([`GpuBackend::new`]) takes the feature whenever the adapter has it; an engine's device
    /// needs it requested.
    pub fn timestamps(&self) -> bool {
        self.timestamp_period.is_some()
    }

    /// Counters and timings summed over every call since the backend was created.
    pub fn total_stats(&self) -> RenderStats {
        self.totals
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    /// Counters and timings of the last [`render`](RasterBackend::render) call (of any thread).
    pub fn last_stats(&self) -> RenderStats {
        self.stats.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// True when the shrunk-occluder sampler renders on this device
    /// ([`sampler::GpuSampler`]): the device has `SHADER_F64`. Otherwise a bake with the GPU
    /// backend samples on the CPU.
    pub fn sampler_on_gpu(&self) -> bool {
        self.device.features().contains(wgpu::Features::SHADER_F64)
    }

    /// True when ray space factorization's charts run on this device
    /// ([`RasterBackend::rsf_charts`]): they were asked there ([`GpuBackend::set_rsf_on_gpu`])
    /// and it has [`wgpu::Features::SHADER_F64`] (the backend's own device takes it whenever
    /// the adapter has it). Otherwise the CPU's charts are used.
    pub fn rsf_on_gpu(&self) -> bool {
        self.rsf_wanted && self.rsf_pipelines.is_some()
    }

    /// Adds work done outside [`RasterBackend::render`] (ray space factorization) to the
    /// totals.
    fn add_totals(&self, s: &RenderStats) {
        self.totals.lock().unwrap_or_else(|e| e.into_inner()).add(s);
    }

    /// The first device loss or uncaptured error reported, as an error.
    fn check_failure(&self) -> Result<(), BackendError> {
        let f = self.failure.lock().unwrap_or_else(|e| e.into_inner());
        match &*f {
            Some(e) => Err(e.clone()),
            None => Ok(()),
        }
    }

    /// Refuses jobs the device cannot hold: a plane or reprojection source outside `1..=max`
    /// pixels per side (the device's largest texture; records pack pixel origins into 16
    /// bits), or a reprojection whose source or windows do not match their sizes.
    fn check_jobs(&self, jobs: &[PlaneJob]) -> Result<(), BackendError> {
        let max = self.limits.max_texture.min(1 << 15);
        let fits = |w: u32, h: u32| (1..=max).contains(&w) && (1..=max).contains(&h);
        for job in jobs {
            let (w, h) = (job.frame.width, job.frame.height);
            if !fits(w, h) {
                return Err(BackendError::PlaneSize {
                    width: w,
                    height: h,
                    max,
                    adapter: self.adapter_name.clone(),
                });
            }
            for rp in &job.reproject {
                let (sw, sh) = (rp.source.width, rp.source.height);
                // A map kept on the device has a stand-in of no pixels (`DepthMap::on_device`):
                // only this backend's table cache knows it.
                let kept_here = rp.source.is_on_device() && self.tables.get(&rp.source).is_some();
                if !fits(sw, sh)
                    || (rp.source.depth.len() != sw as usize * sh as usize && !kept_here)
                    || rp.cols.len() != w as usize
                    || rp.rows.len() != h as usize
                {
                    return Err(BackendError::BadReprojection {
                        width: w,
                        height: h,
                        source_width: sw,
                        source_height: sh,
                        source_pixels: rp.source.depth.len(),
                        cols: rp.cols.len(),
                        rows: rp.rows.len(),
                    });
                }
            }
        }
        Ok(())
    }
}

/// Gives every plane nothing covers and no reprojection sets its map without the GPU (its
/// slice mask, or uncovered), in `out`; returns the others' indexes, in order.
fn skip_the_gpu(
    jobs: &[PlaneJob],
    prepared: &[Prepared],
    out: &mut [Option<PlaneResult>],
) -> Vec<usize> {
    let mut gpu_jobs = Vec::new();
    for (j, p) in prepared.iter().enumerate() {
        if p.out.vertices.is_empty() && p.sweeps.is_empty() && p.counted.is_empty() {
            let mut map = DepthMap::for_frame(&jobs[j].frame);
            if let Some(mask) = &p.mask {
                merge_mask(&mut map, mask);
            }
            out[j] = Some(PlaneResult::Map(map));
        } else {
            gpu_jobs.push(j);
        }
    }
    gpu_jobs
}

impl RasterBackend for GpuBackend {
    fn as_gpu(&self) -> Option<&GpuBackend> {
        Some(self)
    }

    fn stats_summary(&self, cells: usize) -> Option<String> {
        let t = self.total_stats();
        let n = cells.max(1) as f64;
        Some(
            format!(
                "per cell: {:.1} passes, {:.1} draws, {:.1} submissions, {:.0} occluders ({:.0} triangles) drawn, {:.0} KB uploaded, {:.0} KB read back ({:.1} maps; {:.1} sweep maps kept on the device); GPU section {:.1} ms, CPU setup {:.1} ms",
                t.passes as f64 / n,
                t.draws as f64 / n,
                t.submissions as f64 / n,
                t.occluders as f64 / n,
                t.triangles as f64 / n,
                t.bytes_uploaded as f64 / n / 1024.0,
                t.bytes_read_back as f64 / n / 1024.0,
                t.maps_read_back as f64 / n,
                t.kept_maps as f64 / n,
                t.gpu.as_secs_f64() * 1e3 / n,
                t.setup.as_secs_f64() * 1e3 / n,
            ) + &if t.timed_passes > 0 {
                format!(
                    ", GPU passes {:.2} ms (timestamps){}",
                    t.pass_time.as_secs_f64() * 1e3 / n,
                    if t.counted > 0 {
                        format!(
                            ", of which views {:.2} ms for {:.0} counted occluders ({:.0} named \
                             by part)",
                            t.views_time.as_secs_f64() * 1e3 / n,
                            t.counted as f64 / n,
                            t.counted_resident as f64 / n
                        )
                    } else {
                        String::new()
                    }
                )
            } else {
                String::new()
            },
        )
    }

    fn name(&self) -> &'static str {
        "gpu"
    }

    fn counters(&self) -> Option<super::BackendCounters> {
        let t = self.total_stats();
        Some(super::BackendCounters {
            passes: t.passes,
            bytes_uploaded: t.bytes_uploaded,
            bytes_read_back: t.bytes_read_back,
            maps_read_back: t.maps_read_back,
            maps_kept: t.kept_maps,
            setup: t.setup,
            gpu: t.gpu,
            pass_time: (t.timed_passes > 0).then_some(t.pass_time),
        })
    }

    fn adapter(&self) -> Option<String> {
        Some(self.adapter_name.clone())
    }

    fn rsf_on_device(&self) -> bool {
        self.rsf_on_gpu()
    }

    /// The charts on the GPU where they were asked there ([`GpuBackend::set_rsf_on_gpu`]),
    /// the device has `SHADER_F64` and they fit one storage binding; the CPU's otherwise.
    fn rsf_charts(
        &self,
        cell: &crate::geom::DAabb,
        up: usize,
        resolution: u32,
    ) -> Result<Box<dyn super::RsfCharts + '_>, BackendError> {
        self.check_failure()?;
        match &self.rsf_pipelines {
            Some(p)
                if self.rsf_wanted
                    && rsf::GpuRsfCharts::chart_bytes(resolution)
                        <= self
                            .device
                            .limits()
                            .max_storage_buffer_binding_size
                            .min(self.limits.max_buffer) =>
            {
                Ok(Box::new(rsf::GpuRsfCharts::new(
                    self, p, cell, up, resolution,
                )))
            }
            _ => Ok(Box::new(crate::rsf::RayCharts::new(cell, up, resolution))),
        }
    }

    /// Checks the jobs, prepares them on the CPU in parallel, gives the planes that need no
    /// GPU their maps, and renders the others in waves bounded in memory, with a resource pool
    /// of its own (other threads' calls run meanwhile with theirs).
    fn render(&self, jobs: &[PlaneJob]) -> Result<Vec<DepthMap>, BackendError> {
        let none = vec![None; jobs.len()];
        Ok(self
            .render_tested(jobs, &none)?
            .into_iter()
            .map(|r| match r {
                PlaneResult::Map(m) => m,
                PlaneResult::Answers(_) | PlaneResult::Kept(_) => {
                    unreachable!("no queries, no answers")
                }
            })
            .collect())
    }

    fn tests_on_device(&self) -> bool {
        self.tests_wanted && self.box_pipelines.is_some()
    }

    fn pixels_per_device_test(&self) -> usize {
        self.pixels_per_test
    }

    /// Keeps the boxes (six `f64` each) where box tests run on the device and the table fits
    /// one storage binding: the device's table is made here, and each box goes up the first
    /// time a wave's test names it (`resident::ResidentTable::send`; those bytes count as
    /// uploaded).
    fn upload_occludee_boxes(
        &self,
        boxes: &[crate::geom::DAabb],
    ) -> Result<Option<u64>, BackendError> {
        let bytes = boxes.len() as u64 * hdm::BOX_BYTES;
        let binding = self
            .limits
            .max_buffer
            .min(self.device.limits().max_storage_buffer_binding_size);
        let mut slot = self.resident.lock().unwrap_or_else(|e| e.into_inner());
        // The old table goes first (waves in flight hold their own reference).
        *slot = None;
        if !(self.tests_on_device() && self.resident_wanted) || boxes.is_empty() || bytes > binding
        {
            return Ok(None);
        }
        self.check_failure()?;
        let generation = self.next_generation();
        // (Debug builds keep the boxes to check each test's box against the one it names.)
        let check =
            cfg!(debug_assertions).then(|| (boxes.iter()).flat_map(hdm::box_f64s).collect());
        *slot = Some(resident::ResidentTable::given(
            &self.device,
            "resident occludee boxes",
            (boxes.len(), 6),
            generation,
            check,
        )?);
        Ok(Some(generation))
    }

    /// Where the projections are counted on a device that has the views' pipelines, unless
    /// [`GpuBackend::set_resident_parts`] turned the table off.
    fn keeps_occluder_parts(&self) -> bool {
        self.projection == GpuProjection::Counting
            && self.view_pipelines.is_some()
            && self.parts_wanted
    }

    /// Keeps the parts' points (three `f64` each) where the projections are counted
    /// ([`GpuProjection::Counting`]): the device's table is made here, and each part goes up
    /// the first time a wave's counted occluder names it, from that occluder's points (those
    /// bytes count as uploaded; nothing of the table stays on the CPU but in debug builds,
    /// which check every named occluder's points against its part's). A table larger than
    /// one storage binding keeps the parts that fit in one, from the first; occluders naming
    /// the others send their points.
    fn upload_occluder_parts(
        &self,
        points: &[glam::DVec3],
        spans: &[(u32, u32)],
    ) -> Result<Option<u64>, BackendError> {
        let binding = self
            .limits
            .max_buffer
            .min(self.device.limits().max_storage_buffer_binding_size);
        let mut slot = self
            .resident_parts
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        // The old table goes first (waves in flight hold their own reference).
        *slot = None;
        let (kept, end) = resident::parts_that_fit(spans, points.len(), binding);
        if !self.keeps_occluder_parts() || end == 0 {
            return Ok(None);
        }
        self.check_failure()?;
        let generation = self.next_generation();
        // (Debug builds keep the points to check each named occluder's against its part's.)
        let check = cfg!(debug_assertions)
            .then(|| points[..end].iter().flat_map(|p| p.to_array()).collect());
        let points = resident::ResidentTable::given(
            &self.device,
            "resident occluder points",
            (end, 3),
            generation,
            check,
        )?;
        *slot = Some(resident::ResidentParts {
            points,
            spans: spans[..kept].into(),
        });
        Ok(Some(generation))
    }

    fn render_tested(
        &self,
        jobs: &[PlaneJob],
        queries: &[Option<PlaneQueries>],
    ) -> Result<Vec<PlaneResult>, BackendError> {
        self.render_kept(jobs, queries, &vec![false; jobs.len()])
    }

    fn keeps_maps(&self) -> bool {
        self.tests_wanted && self.keep_wanted
    }

    fn render_kept(
        &self,
        jobs: &[PlaneJob],
        queries: &[Option<PlaneQueries>],
        keep: &[bool],
    ) -> Result<Vec<PlaneResult>, BackendError> {
        assert_eq!(
            jobs.len(),
            queries.len(),
            "one query list (or None) per job"
        );
        assert_eq!(jobs.len(), keep.len(), "one keep flag per job");
        // A map kept without its queries could answer nothing: kept maps are tested ones.
        let keep: Vec<bool> = (keep.iter().zip(queries))
            .map(|(&k, q)| k && q.is_some() && self.keep_wanted)
            .collect();
        self.check_failure()?;
        self.check_jobs(jobs)?;
        let t0 = Instant::now();
        self.tables.evict();
        let mut stats = RenderStats {
            planes: jobs.len(),
            ..RenderStats::default()
        };
        let prepared: Vec<Prepared> = jobs
            .par_iter()
            .map(|j| {
                prepare(
                    j,
                    self.limits.max_chunk_words,
                    self.projection == GpuProjection::Counting,
                    &self.tables,
                )
            })
            .collect::<Result<_, _>>()?;
        stats.setup = t0.elapsed();
        let mut out: Vec<Option<PlaneResult>> = vec![None; jobs.len()];
        let gpu_jobs = skip_the_gpu(jobs, &prepared, &mut out);
        let waves = plan_waves(jobs, &prepared, &gpu_jobs, &self.limits);
        stats.gpu_planes = gpu_jobs.len();
        if !waves.is_empty() {
            // A pool of this call's own: other threads' calls run meanwhile with theirs.
            let mut pool = self
                .pools
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .pop()
                .unwrap_or_default();
            let t1 = Instant::now();
            let done = waves.iter().try_for_each(|wave| {
                self.render_wave(
                    &mut pool,
                    jobs,
                    &prepared,
                    (queries, &keep),
                    wave,
                    &mut out,
                    &mut stats,
                )
            });
            self.pools
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .push(pool);
            done?;
            stats.gpu = t1.elapsed();
        }
        stats.total = t0.elapsed();
        self.totals
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .add(&stats);
        *self.stats.lock().unwrap_or_else(|e| e.into_inner()) = stats;
        Ok(out
            .into_iter()
            .map(|m| m.expect("every job rendered"))
            .collect())
    }
}
