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
//! During the setup (parallel, outside the lock) the CPU builds per reprojection the table of
//! its source's pixels *outside* the umbra (entry `(x, y)` counts those in `[0, x] × [0, y]`, with
//! the CPU's `d <= 0` test, so NaNs are outside), one pass over the source it had to read
//! anyway; the table is uploaded with `queue.write_texture` into a pooled `R32Uint` texture,
//! and the windows, after a 16-byte header (the Depth, the resolution, `+inf`), into a shared
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
//! machine), for ~45 µs of CPU per table; no intermediate texture, and no extra render pass. The tables of a call's jobs are held in memory until the
//! call returns (`w × h × 4` bytes per reprojection for a `w × h` source, as much as the
//! sources).
//!
//! # Per `render` call
//!
//! All jobs (a cell's 6–30 planes) are prepared in parallel, uploaded into shared, grown-only
//! vertex/data/uniform buffers, encoded in one command buffer — per plane one render pass, one
//! draw per chunk of the data buffer (one chunk unless the plane's data exceed the device's
//! storage binding size) and per reprojection, one texture-to-buffer copy — and submitted once;
//! then all staging buffers are mapped at once and the device is polled with a timeout. Render
//! targets, staging buffers and reprojection tables are pooled per map size (`width × height`:
//! sweep planes' maps are stretched, and a reprojection's source may differ from its target). Planes no
//! occluder can cover and no reprojection can set skip the GPU. Jobs are split into several
//! submissions only to bound memory (256 MiB of targets, read-back buffers and tables, 512 MiB
//! of data). The CPU setup runs outside the backend's lock, so cells baked on several threads
//! prepare their planes while another cell's are on the GPU.
//!
//! Per `w × h` plane: 1 render pass, 1 draw (≈ 1.2 triangles per occluder drawn), `w × h × 4`
//! bytes read back (rows padded to 256 bytes, i.e. `256 × h` bytes when `w < 64`). Each
//! reprojection from a `sw × sh` source adds 1 draw and `sw × sh × 4 + 8·(w + h + 3)` bytes
//! uploaded, and `sw × sh × 4` bytes of texture to the submission's memory budget. See [`GpuBackend::last_stats`].
//!
//! Device loss, out-of-memory and validation errors become [`BackendError::Device`]: errors are
//! caught by error scopes and by an uncaptured-error handler, loss by the device-lost callback,
//! and waits poll with a timeout, so a failing device never hangs a bake.

pub mod setup;

use super::{BackendError, RasterBackend, coverage};
use crate::plane::{DepthMap, PlaneJob, Reprojection, Window};
use rayon::prelude::*;
use setup::{Output, PlaneSetup, Scratch, Vertex};
use std::collections::HashMap;
use std::num::NonZeroU64;
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The WGSL source of every pass, `(file name, source)`, for validation in tests.
pub const SHADERS: &[(&str, &str)] = &[
    (
        "shaders/projection.wgsl",
        include_str!("../../../shaders/projection.wgsl"),
    ),
    (
        "shaders/reproject.wgsl",
        include_str!("../../../shaders/reproject.wgsl"),
    ),
];

const PROJECTION_WGSL: &str = SHADERS[0].1;
const REPROJECT_WGSL: &str = SHADERS[1].1;

/// Occluders per rayon task of the setup.
const SETUP_TASK: usize = 1024;
/// Bytes of render targets + staging buffers one submission may use.
const TARGET_BUDGET: u64 = 256 << 20;
/// Bytes of vertex + record/edge data one submission may use (also capped by the device).
const DATA_BUDGET: u64 = 512 << 20;
/// Stride of per-plane uniforms (WebGPU's maximum `min_uniform_buffer_offset_alignment`).
const UNIFORM_STRIDE: u64 = 256;
/// How long one poll blocks before the device-lost flag and the deadline are checked again.
const POLL_SLICE: Duration = Duration::from_millis(250);
/// A submission not finished after this long is reported as a device failure.
const DEADLINE: Duration = Duration::from_secs(600);

/// The wgpu backend. Instance, adapter, device, pipeline and pools are created once, in
/// [`GpuBackend::new`]; every [`render`](RasterBackend::render) call reuses them.
pub struct GpuBackend {
    adapter_name: String,
    device: wgpu::Device,
    queue: wgpu::Queue,
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    /// The reprojections' draw (into the plane's target) and its bind group layout.
    reproject: wgpu::RenderPipeline,
    reproject_layout: wgpu::BindGroupLayout,
    /// First device-lost or uncaptured error message; once set, every call fails.
    failure: Arc<Mutex<Option<String>>>,
    /// Largest storage binding, in 16-byte words.
    max_chunk_words: usize,
    storage_align: u64,
    max_buffer: u64,
    max_texture: u32,
    pool: Mutex<Pool>,
    stats: Mutex<RenderStats>,
    /// Sums over every call since creation.
    totals: Mutex<RenderStats>,
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
    pub triangles: usize,
    pub edges: usize,
    /// Bytes written to GPU buffers and textures (vertices, records and edges, uniforms,
    /// reprojection windows and summed-area tables).
    pub bytes_uploaded: u64,
    /// Bytes copied back from the GPU (padded rows included).
    pub bytes_read_back: u64,
    /// Wall time of the CPU setup (parallel), of the GPU section (upload to read-back), total.
    pub setup: Duration,
    pub gpu: Duration,
    pub total: Duration,
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
        self.bytes_uploaded += o.bytes_uploaded;
        self.bytes_read_back += o.bytes_read_back;
        self.setup += o.setup;
        self.gpu += o.gpu;
        self.total += o.total;
    }
}

/// GPU resources reused across calls.
#[derive(Default)]
struct Pool {
    vertices: Option<wgpu::Buffer>,
    data: Option<wgpu::Buffer>,
    uniforms: Option<wgpu::Buffer>,
    /// Reprojection windows of every reprojection of a submission.
    windows: Option<wgpu::Buffer>,
    /// Per map size `(width, height)`.
    targets: HashMap<(u32, u32), Vec<Target>>,
    /// Reprojections' summed-area tables, one per reprojection of a submission, per source
    /// size.
    tables: HashMap<(u32, u32), Vec<SweepTable>>,
}

/// One plane's render target and its read-back buffer.
struct Target {
    view: wgpu::TextureView,
    texture: wgpu::Texture,
    staging: wgpu::Buffer,
    padded_row: u32,
}

/// One reprojection's summed-area table (see [`SweepSetup::table`]).
struct SweepTable {
    texture: wgpu::Texture,
    view: wgpu::TextureView,
}

/// A job's CPU-side preparation.
struct Prepared {
    /// Records, edges and geometry; vertices' record indices are relative to their chunk.
    out: Output,
    occluders: usize,
    /// Draw chunks: vertex range and data range.
    chunks: Vec<Chunk>,
    /// The slices as a map (`0` inside, `+inf` elsewhere), merged on read-back.
    mask: Option<DepthMap>,
    /// The job's reprojections that can set a pixel, in the job's order.
    sweeps: Vec<SweepSetup>,
}

/// One reprojection of a job, prepared for the GPU (see [`sweep_setup`]).
#[derive(Clone, Debug, PartialEq)]
struct SweepSetup {
    /// The storage data: `[depth bits, target width]`, `[+inf bits, source width]`,
    /// `[source height, 0]`, then the column windows, then the row windows
    /// (`shaders/reproject.wgsl`).
    words: Vec<[u32; 2]>,
    /// The source's (and the table's) `(width, height)`.
    source_size: (u32, u32),
    /// The source's summed-area table of pixels outside the umbra, row-major: entry `(x, y)`
    /// counts the source pixels in `[0, x] × [0, y]` whose Depth is not `≤ 0`.
    table: Vec<u32>,
    /// The draw's scissor rectangle `[x, y, width, height]`: the bounding box of the target
    /// pixels the reprojection may set.
    scissor: [u32; 4],
}

#[derive(Clone, Debug)]
struct Chunk {
    vertices: std::ops::Range<u32>,
    data: std::ops::Range<usize>,
}

/// Adapter ranking: hardware first, software rasterisers last.
fn rank(t: wgpu::DeviceType) -> u32 {
    match t {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Other => 3,
        wgpu::DeviceType::Cpu => 4,
    }
}

fn new_instance() -> wgpu::Instance {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
    if desc.backends.is_empty() {
        desc.backends = wgpu::Backends::PRIMARY;
    }
    wgpu::Instance::new(desc)
}

/// Features the backend needs from an adapter.
const REQUIRED_FEATURES: wgpu::Features = wgpu::Features::FLOAT32_BLENDABLE;

/// The adapters this backend can use, best first, with the reasons the others were rejected.
fn usable_adapters(instance: &wgpu::Instance) -> (Vec<wgpu::Adapter>, Vec<String>) {
    let all = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
    let mut rejected = Vec::new();
    let mut ok: Vec<wgpu::Adapter> = all
        .into_iter()
        .filter(|a| {
            let info = a.get_info();
            if !a.features().contains(REQUIRED_FEATURES) {
                rejected.push(format!(
                    "{} ({:?}): no float32-blendable support",
                    info.name, info.backend
                ));
                return false;
            }
            true
        })
        .collect();
    ok.sort_by_key(|a| rank(a.get_info().device_type));
    (ok, rejected)
}

/// True when a real (non-CPU) GPU adapter that this backend can use exists: the CLI's
/// `--backend auto` picks the GPU backend only then (software rasterisers such as llvmpipe are
/// slower than the CPU backend).
pub fn hardware_adapter_available() -> bool {
    let instance = new_instance();
    let (adapters, _) = usable_adapters(&instance);
    adapters
        .iter()
        .any(|a| a.get_info().device_type != wgpu::DeviceType::Cpu)
}

impl GpuBackend {
    /// Creates the instance, picks the best adapter (hardware before software), and creates
    /// the device, the pipeline and empty resource pools.
    ///
    /// `WGPU_BACKEND` (e.g. `vulkan`) restricts the backends searched.
    ///
    /// # Errors
    /// [`BackendError::NoAdapter`] when no adapter exists or none supports `float32-blendable`
    /// render targets; [`BackendError::Device`] when the device or pipeline cannot be created.
    pub fn new() -> Result<Self, BackendError> {
        let instance = new_instance();
        let (adapters, rejected) = usable_adapters(&instance);
        let Some(adapter) = adapters.into_iter().next() else {
            let why = if rejected.is_empty() {
                "no Vulkan, Metal or DX12 adapter is present (on Linux without a GPU, install \
                 Mesa's software Vulkan driver: `apt-get install mesa-vulkan-drivers`)"
                    .to_string()
            } else {
                format!("no adapter is usable: {}", rejected.join("; "))
            };
            return Err(BackendError::NoAdapter(why));
        };
        let info = adapter.get_info();
        let limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("umbrasweep device"),
            required_features: REQUIRED_FEATURES,
            required_limits: limits.clone(),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .map_err(|e| {
            BackendError::Device(format!("cannot create a device on {}: {e}", info.name))
        })?;

        let failure: Arc<Mutex<Option<String>>> = Arc::default();
        {
            let failure = failure.clone();
            device.set_device_lost_callback(move |reason, message| {
                let mut f = failure.lock().unwrap_or_else(|e| e.into_inner());
                f.get_or_insert(format!("device lost ({reason:?}): {message}"));
            });
        }
        {
            let failure = failure.clone();
            device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
                let mut f = failure.lock().unwrap_or_else(|e| e.into_inner());
                f.get_or_insert(format!("uncaptured GPU error: {e}"));
            }));
        }

        let scope = ErrorScopes::push(&device);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("shaders/projection.wgsl"),
            source: wgpu::ShaderSource::Wgsl(PROJECTION_WGSL.into()),
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("projection bind group layout"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::VERTEX,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: NonZeroU64::new(16),
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: true },
                        has_dynamic_offset: false,
                        min_binding_size: NonZeroU64::new(16),
                    },
                    count: None,
                },
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("projection pipeline layout"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let attributes = wgpu::vertex_attr_array![0 => Float32x2, 1 => Uint32];
        let blend = wgpu::BlendComponent {
            src_factor: wgpu::BlendFactor::One,
            dst_factor: wgpu::BlendFactor::One,
            operation: wgpu::BlendOperation::Min,
        };
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("projection pipeline"),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[Some(wgpu::VertexBufferLayout {
                    array_stride: std::mem::size_of::<Vertex>() as u64,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &attributes,
                })],
            },
            primitive: wgpu::PrimitiveState {
                topology: wgpu::PrimitiveTopology::TriangleList,
                cull_mode: None,
                ..Default::default()
            },
            depth_stencil: None,
            multisample: wgpu::MultisampleState::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &[Some(depth_min_target(blend))],
            }),
            multiview_mask: None,
            cache: None,
        });
        let (reproject, reproject_layout) = reproject_pipeline(&device, blend);
        scope.check()?;

        let storage_align = limits.min_storage_buffer_offset_alignment.max(16) as u64;
        let max_binding = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        let max_chunk_words = ((max_binding / storage_align * storage_align) / 16) as usize;
        Ok(GpuBackend {
            adapter_name: info.name.clone(),
            device,
            queue,
            pipeline,
            layout,
            reproject,
            reproject_layout,
            failure,
            max_chunk_words,
            storage_align,
            max_buffer: limits.max_buffer_size,
            max_texture: limits.max_texture_dimension_2d,
            pool: Mutex::default(),
            stats: Mutex::default(),
            totals: Mutex::default(),
        })
    }

    /// The adapter's information (name, backend, device type, driver).
    pub fn adapter_info(&self) -> wgpu::AdapterInfo {
        self.device.adapter_info()
    }

    /// Destroys the device, as a driver reset would lose it: every later call fails with
    /// [`BackendError::Device`]. For tests of the failure path.
    #[doc(hidden)]
    pub fn simulate_device_loss(&self) {
        self.device.destroy();
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

    fn check_failure(&self) -> Result<(), BackendError> {
        let f = self.failure.lock().unwrap_or_else(|e| e.into_inner());
        match &*f {
            Some(msg) => Err(BackendError::Device(msg.clone())),
            None => Ok(()),
        }
    }

    /// CPU setup of one job: records, edges and geometry of every occluder, split into draw
    /// chunks whose data fits one storage binding.
    fn prepare(&self, job: &PlaneJob) -> Result<Prepared, BackendError> {
        let frame = &job.frame;
        let ps = PlaneSetup::new(frame);
        let n = job.occluders.len();
        let parts: Vec<(Output, usize)> = (0..n.div_ceil(SETUP_TASK))
            .into_par_iter()
            .map(|t| {
                let mut scratch = Scratch::default();
                let mut out = Output::default();
                let mut count = 0;
                for k in t * SETUP_TASK..((t + 1) * SETUP_TASK).min(n) {
                    let pts = job.occluders.get(k);
                    let depth = pts
                        .iter()
                        .map(|&p| frame.depth(p))
                        .fold(f64::NEG_INFINITY, f64::max);
                    if setup::occluder(&ps, pts, depth, &mut scratch, &mut out) {
                        count += 1;
                    }
                }
                (out, count)
            })
            .collect();
        let mut out = Output {
            data: Vec::with_capacity(parts.iter().map(|p| p.0.data.len()).sum()),
            vertices: Vec::with_capacity(parts.iter().map(|p| p.0.vertices.len()).sum()),
        };
        let mut occluders = 0;
        for (part, count) in parts {
            let base = out.data.len() as u32;
            out.data.extend_from_slice(&part.data);
            out.vertices.extend(part.vertices.iter().map(|v| Vertex {
                record: v.record + base,
                ..*v
            }));
            occluders += count;
        }
        // Split into chunks whose data fits one storage binding; rebase record indices.
        let mut chunks = Vec::new();
        let (mut first, mut base, mut current) = (0usize, 0usize, u32::MAX);
        for k in 0..out.vertices.len() {
            let rec = out.vertices[k].record;
            if rec != current {
                current = rec;
                let end = rec as usize + 1 + out.data[rec as usize][2] as usize;
                if end - rec as usize > self.max_chunk_words {
                    return Err(BackendError::Device(format!(
                        "an occluder has {} edges, more than one storage binding holds",
                        end - rec as usize - 1
                    )));
                }
                if end - base > self.max_chunk_words {
                    chunks.push(Chunk {
                        vertices: first as u32..k as u32,
                        data: base..rec as usize,
                    });
                    first = k;
                    base = rec as usize;
                }
            }
            out.vertices[k].record = rec - base as u32;
        }
        if first < out.vertices.len() {
            chunks.push(Chunk {
                vertices: first as u32..out.vertices.len() as u32,
                data: base..out.data.len(),
            });
        }
        Ok(Prepared {
            out,
            occluders,
            chunks,
            mask: slice_mask(job),
            sweeps: job.reproject.par_iter().filter_map(sweep_setup).collect(),
        })
    }

    /// Makes `slot` a buffer of at least `size` bytes (grown to a power of two, never shrunk).
    fn ensure_buffer(
        &self,
        slot: &mut Option<wgpu::Buffer>,
        size: u64,
        usage: wgpu::BufferUsages,
        label: &str,
    ) -> Result<(), BackendError> {
        if slot.as_ref().is_some_and(|b| b.size() >= size) {
            return Ok(());
        }
        if size > self.max_buffer {
            return Err(BackendError::Device(format!(
                "{label}: {size} bytes exceed the device's maximum buffer size {}",
                self.max_buffer
            )));
        }
        let cap = size
            .next_power_of_two()
            .clamp(1 << 16, self.max_buffer.max(size));
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

    fn new_target(&self, (w, h): (u32, u32)) -> Target {
        let (texture, view) = self.map_texture(
            "depth map",
            (w, h),
            wgpu::TextureFormat::R32Float,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
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

    fn new_sweep_table(&self, size: (u32, u32)) -> SweepTable {
        let (texture, view) = self.map_texture(
            "reprojection table",
            size,
            wgpu::TextureFormat::R32Uint,
            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        );
        SweepTable { texture, view }
    }

    /// Renders one submission's worth of jobs (`todo` indexes `jobs` and `prepared`).
    fn render_wave(
        &self,
        pool: &mut Pool,
        jobs: &[PlaneJob],
        prepared: &[Prepared],
        todo: &[usize],
        out: &mut [Option<DepthMap>],
        stats: &mut RenderStats,
    ) -> Result<(), BackendError> {
        let scope = ErrorScopes::push(&self.device);
        // Layout of the shared buffers.
        let vert_size = std::mem::size_of::<Vertex>() as u64;
        let mut vert_total = 0u64;
        let mut data_total = 0u64;
        let mut first_vertex = Vec::with_capacity(todo.len());
        let mut chunk_offsets: Vec<Vec<u64>> = Vec::with_capacity(todo.len());
        for &j in todo {
            let p = &prepared[j];
            first_vertex.push((vert_total / vert_size) as u32);
            vert_total += p.out.vertices.len() as u64 * vert_size;
            let mut offs = Vec::with_capacity(p.chunks.len());
            for c in &p.chunks {
                offs.push(data_total);
                data_total += ((c.data.len() as u64) * 16).next_multiple_of(self.storage_align);
            }
            chunk_offsets.push(offs);
        }
        // Reprojection windows: one aligned range per reprojection.
        let mut windows_total = 0u64;
        let windows_offsets: Vec<Vec<u64>> = todo
            .iter()
            .map(|&j| {
                prepared[j]
                    .sweeps
                    .iter()
                    .map(|sw| {
                        let off = windows_total;
                        windows_total +=
                            (sw.words.len() as u64 * 8).next_multiple_of(self.storage_align);
                        off
                    })
                    .collect()
            })
            .collect();
        if windows_total > 0 {
            self.ensure_buffer(
                &mut pool.windows,
                windows_total,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                "reprojection windows",
            )?;
        }
        self.ensure_buffer(
            &mut pool.vertices,
            vert_total.max(vert_size),
            wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
            "occluder geometry",
        )?;
        self.ensure_buffer(
            &mut pool.data,
            data_total.max(16),
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            "occluder records and view edges",
        )?;
        self.ensure_buffer(
            &mut pool.uniforms,
            todo.len() as u64 * UNIFORM_STRIDE,
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            "plane uniforms",
        )?;
        let (Some(vert_buf), Some(data_buf), Some(uni_buf)) =
            (&pool.vertices, &pool.data, &pool.uniforms)
        else {
            unreachable!("buffers were just ensured");
        };
        let win_buf = pool.windows.as_ref();
        // Upload.
        let mut uniforms = vec![0u8; todo.len() * UNIFORM_STRIDE as usize];
        for (w, &j) in todo.iter().enumerate() {
            let p = &prepared[j];
            if !p.out.vertices.is_empty() {
                self.queue.write_buffer(
                    vert_buf,
                    first_vertex[w] as u64 * vert_size,
                    bytemuck::cast_slice(&p.out.vertices),
                );
            }
            for (c, &off) in p.chunks.iter().zip(&chunk_offsets[w]) {
                if !c.data.is_empty() {
                    self.queue.write_buffer(
                        data_buf,
                        off,
                        bytemuck::cast_slice(&p.out.data[c.data.clone()]),
                    );
                }
            }
            if let Some(buf) = win_buf {
                for (sw, &off) in p.sweeps.iter().zip(&windows_offsets[w]) {
                    self.queue
                        .write_buffer(buf, off, bytemuck::cast_slice(sw.words.as_slice()));
                }
            }
            let f = &jobs[j].frame;
            let o = w * UNIFORM_STRIDE as usize;
            uniforms[o..o + 4].copy_from_slice(&(2.0f32 / f.width as f32).to_le_bytes());
            uniforms[o + 4..o + 8].copy_from_slice(&(2.0f32 / f.height as f32).to_le_bytes());
        }
        self.queue.write_buffer(uni_buf, 0, &uniforms);
        stats.submissions += 1;
        stats.passes += todo.len();
        stats.bytes_uploaded += vert_total + uniforms.len() as u64;
        for &j in todo {
            let p = &prepared[j];
            for sw in &p.sweeps {
                stats.reprojections += 1;
                stats.draws += 1;
                stats.bytes_uploaded += (sw.words.len() * 8 + sw.table.len() * 4) as u64;
            }
            stats.draws += p.chunks.len();
            stats.occluders += p.occluders;
            stats.triangles += p.out.vertices.len() / 3;
            stats.edges += p.out.data.len() - p.occluders;
            stats.bytes_uploaded += p.out.data.len() as u64 * 16;
            let f = &jobs[j].frame;
            stats.bytes_read_back += (f.width as u64 * 4).next_multiple_of(256) * f.height as u64;
        }

        // Targets from the pool, per map size.
        let mut taken: HashMap<(u32, u32), usize> = HashMap::new();
        let mut slots = Vec::with_capacity(todo.len());
        for &j in todo {
            let size = (jobs[j].frame.width, jobs[j].frame.height);
            let k = taken.entry(size).or_default();
            let list = pool.targets.entry(size).or_default();
            if list.len() <= *k {
                list.push(self.new_target(size));
            }
            slots.push((size, *k));
            *k += 1;
        }
        // Reprojection tables from the pool, per source size, one per reprojection; uploaded.
        let mut taken: HashMap<(u32, u32), usize> = HashMap::new();
        let mut table_slots: Vec<Vec<((u32, u32), usize)>> = Vec::with_capacity(todo.len());
        for &j in todo {
            let mut mine = Vec::with_capacity(prepared[j].sweeps.len());
            for sw in &prepared[j].sweeps {
                let size = sw.source_size;
                let (width, height) = size;
                let k = taken.entry(size).or_default();
                let list = pool.tables.entry(size).or_default();
                if list.len() <= *k {
                    list.push(self.new_sweep_table(size));
                }
                self.queue.write_texture(
                    wgpu::TexelCopyTextureInfo {
                        texture: &list[*k].texture,
                        mip_level: 0,
                        origin: wgpu::Origin3d::ZERO,
                        aspect: wgpu::TextureAspect::All,
                    },
                    bytemuck::cast_slice(&sw.table),
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
                mine.push((size, *k));
                *k += 1;
            }
            table_slots.push(mine);
        }
        // The reprojections' bind groups: windows and table.
        let mut reproject_groups: Vec<Vec<wgpu::BindGroup>> = Vec::with_capacity(todo.len());
        for (w, &j) in todo.iter().enumerate() {
            let groups = prepared[j]
                .sweeps
                .iter()
                .zip(&table_slots[w])
                .zip(&windows_offsets[w])
                .map(|((sw, &(size, k)), &off)| {
                    let Some(buf) = win_buf else {
                        unreachable!("the windows buffer exists when a plane reprojects");
                    };
                    self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                        label: Some("reprojection bind group"),
                        layout: &self.reproject_layout,
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
                                resource: wgpu::BindingResource::TextureView(
                                    &pool.tables[&size][k].view,
                                ),
                            },
                        ],
                    })
                })
                .collect();
            reproject_groups.push(groups);
        }

        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("umbrasweep planes"),
            });
        // Encode every plane: one pass, one draw per chunk and one per reprojection, one copy.
        for (w, &j) in todo.iter().enumerate() {
            let p = &prepared[j];
            let (size, k) = slots[w];
            let target = &pool.targets[&size][k];
            let bind_groups: Vec<wgpu::BindGroup> = p
                .chunks
                .iter()
                .zip(&chunk_offsets[w])
                .map(|(c, &off)| {
                    let size = ((c.data.len() as u64) * 16).max(16);
                    self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                        label: Some("projection chunk bind group"),
                        layout: &self.layout,
                        entries: &[
                            wgpu::BindGroupEntry {
                                binding: 0,
                                resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                                    buffer: uni_buf,
                                    offset: w as u64 * UNIFORM_STRIDE,
                                    size: NonZeroU64::new(16),
                                }),
                            },
                            wgpu::BindGroupEntry {
                                binding: 1,
                                resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                                    buffer: data_buf,
                                    offset: off,
                                    size: NonZeroU64::new(size),
                                }),
                            },
                        ],
                    })
                })
                .collect();
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
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                });
                if !p.chunks.is_empty() {
                    pass.set_pipeline(&self.pipeline);
                    pass.set_vertex_buffer(0, vert_buf.slice(..));
                    let base = first_vertex[w];
                    for (c, bg) in p.chunks.iter().zip(&bind_groups) {
                        pass.set_bind_group(0, bg, &[]);
                        pass.draw(base + c.vertices.start..base + c.vertices.end, 0..1);
                    }
                }
                if !p.sweeps.is_empty() {
                    pass.set_pipeline(&self.reproject);
                    for (sw, bg) in p.sweeps.iter().zip(&reproject_groups[w]) {
                        let [x, y, width, height] = sw.scissor;
                        pass.set_scissor_rect(x, y, width, height);
                        pass.set_bind_group(0, bg, &[]);
                        pass.draw(0..3, 0..1);
                    }
                }
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
        let submission = self.queue.submit([encoder.finish()]);
        let (tx, rx) = mpsc::channel::<(usize, Result<(), wgpu::BufferAsyncError>)>();
        for (w, &(size, k)) in slots.iter().enumerate() {
            let tx = tx.clone();
            pool.targets[&size][k]
                .staging
                .map_async(wgpu::MapMode::Read, .., move |r| {
                    let _ = tx.send((w, r));
                });
        }
        drop(tx);
        scope.check()?;

        // Wait, polling with a timeout so a lost device cannot hang us.
        let start = Instant::now();
        let mut mapped = vec![false; todo.len()];
        let mut remaining = todo.len();
        while remaining > 0 {
            self.check_failure()?;
            match self.device.poll(wgpu::PollType::Wait {
                submission_index: Some(submission.clone()),
                timeout: Some(POLL_SLICE),
            }) {
                Ok(_) | Err(wgpu::PollError::Timeout) => {}
                Err(e) => {
                    self.check_failure()?;
                    return Err(BackendError::Device(format!("poll failed: {e}")));
                }
            }
            while let Ok((w, r)) = rx.try_recv() {
                r.map_err(|e| BackendError::Device(format!("read-back failed: {e}")))?;
                if !mapped[w] {
                    mapped[w] = true;
                    remaining -= 1;
                }
            }
            if remaining > 0 && start.elapsed() > DEADLINE {
                return Err(BackendError::Device(format!(
                    "the GPU did not finish {} planes within {DEADLINE:?}",
                    todo.len()
                )));
            }
        }
        self.check_failure()?;

        // Read back, merge the slice masks.
        for (w, &j) in todo.iter().enumerate() {
            let ((width, height), k) = slots[w];
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
                    .map_err(|e| BackendError::Device(format!("read-back mapping: {e}")))?;
                let row_bytes = width as usize * 4;
                for row in view.chunks(target.padded_row as usize) {
                    map.depth
                        .extend_from_slice(bytemuck::cast_slice::<u8, f32>(&row[..row_bytes]));
                }
            }
            target.staging.unmap();
            if let Some(mask) = &prepared[j].mask {
                merge_mask(&mut map, mask);
            }
            out[j] = Some(map);
        }
        Ok(())
    }
}

/// The colour target of every pass into a Depth Map: `R32Float`, red only, blended with
/// `blend` (the `Min` operation).
fn depth_min_target(blend: wgpu::BlendComponent) -> wgpu::ColorTargetState {
    wgpu::ColorTargetState {
        format: wgpu::TextureFormat::R32Float,
        blend: Some(wgpu::BlendState {
            color: blend,
            alpha: blend,
        }),
        write_mask: wgpu::ColorWrites::RED,
    }
}

/// The reprojections' pipeline (a fullscreen triangle into the `R32Float` Depth Map with
/// `blend`) and its bind group layout: the windows (storage) and the summed-area table.
fn reproject_pipeline(
    device: &wgpu::Device,
    blend: wgpu::BlendComponent,
) -> (wgpu::RenderPipeline, wgpu::BindGroupLayout) {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("shaders/reproject.wgsl"),
        source: wgpu::ShaderSource::Wgsl(REPROJECT_WGSL.into()),
    });
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("reprojection bind group layout"),
        entries: &[
            wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only: true },
                    has_dynamic_offset: false,
                    // The header (six words) and one window.
                    min_binding_size: NonZeroU64::new(32),
                },
                count: None,
            },
            wgpu::BindGroupLayoutEntry {
                binding: 1,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Uint,
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                count: None,
            },
        ],
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("reprojection pipeline layout"),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("reprojection pipeline"),
        layout: Some(&pipeline_layout),
        vertex: wgpu::VertexState {
            module: &module,
            entry_point: Some("vs_fullscreen"),
            compilation_options: Default::default(),
            buffers: &[],
        },
        primitive: wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::TriangleList,
            cull_mode: None,
            ..Default::default()
        },
        depth_stencil: None,
        multisample: wgpu::MultisampleState::default(),
        fragment: Some(wgpu::FragmentState {
            module: &module,
            entry_point: Some("fs_reproject"),
            compilation_options: Default::default(),
            targets: &[Some(depth_min_target(blend))],
        }),
        multiview_mask: None,
        cache: None,
    });
    (pipeline, layout)
}

/// A reprojection prepared for the GPU, or `None` when it cannot set a pixel.
///
/// The summed-area table of the source's pixels outside the umbra is built in one pass over
/// the source (the same `d <= 0` test as [`Reprojection::mask`]). A target pixel `(i, j)` can
/// only be set when its windows are valid and `cols[i] × rows[j]` lies inside the bounding box
/// of the umbra (every column and row of the box then holds an umbra pixel); the draw is
/// scissored to the bounding box of those pixels, and outside it a draw would write `+inf`
/// anyway. No umbra, or no such pixel: `None`.
fn sweep_setup(r: &Reprojection) -> Option<SweepSetup> {
    let (sw, sh) = (r.source.width, r.source.height);
    let (n, m) = (sw as usize, sh as usize);
    // Windows first: O(width + height), and a reprojection without any skips the table.
    let any_valid = |w: &[Window], len: u32| w.iter().any(|&[a, b]| a <= b && b < len);
    if !any_valid(&r.cols, sw) || !any_valid(&r.rows, sh) {
        return None;
    }
    let mut table = vec![0u32; n * m];
    for (y, src) in r.source.depth.chunks_exact(n).enumerate() {
        let (done, rest) = table.split_at_mut(y * n);
        let row = &mut rest[..n];
        // The row's prefix count of pixels outside the umbra (not `d <= 0`: NaNs are outside)…
        let mut run = 0u32;
        for (t, &d) in row.iter_mut().zip(src) {
            run += u32::from(d <= 0.0) ^ 1;
            *t = run;
        }
        // …plus the rows above.
        if y > 0 {
            for (t, &a) in row.iter_mut().zip(&done[(y - 1) * n..]) {
                *t += a;
            }
        }
    }
    let last = &table[(m - 1) * n..];
    if last[n - 1] as usize == n * m {
        return None;
    }
    // The umbra's bounding box [x0, x1] × [y0, y1]: the columns and rows not entirely outside.
    let column = |x: usize| last[x] - if x > 0 { last[x - 1] } else { 0 };
    let row = |y: usize| table[y * n + n - 1] - if y > 0 { table[y * n - 1] } else { 0 };
    let bounds = |full: &dyn Fn(usize) -> u32, count: usize, len: u32| {
        let lo = (0..count).position(|k| full(k) < len)?;
        let hi = (0..count).rposition(|k| full(k) < len)?;
        Some((lo as u32, hi as u32))
    };
    // A column holds `sh` pixels, a row `sw`.
    let ((x0, x1), (y0, y1)) = (bounds(&column, n, sh)?, bounds(&row, m, sw)?);
    // The range of indices whose window lies inside [lo, hi].
    let inside = |windows: &[Window], lo: u32, hi: u32| {
        let ok = |&[a, b]: &Window| a <= b && a >= lo && b <= hi;
        let first = windows.iter().position(ok)? as u32;
        let last = windows.iter().rposition(ok)? as u32;
        Some((first, last))
    };
    let (i0, i1) = inside(&r.cols, x0, x1)?;
    let (j0, j1) = inside(&r.rows, y0, y1)?;
    let mut words = Vec::with_capacity(3 + r.cols.len() + r.rows.len());
    words.push([r.depth.to_bits(), r.cols.len() as u32]);
    words.push([f32::INFINITY.to_bits(), sw]);
    words.push([sh, 0]);
    words.extend_from_slice(&r.cols);
    words.extend_from_slice(&r.rows);
    Some(SweepSetup {
        words,
        source_size: (sw, sh),
        table,
        scissor: [i0, j0, i1 - i0 + 1, j1 - j0 + 1],
    })
}

/// The job's slices as a map: `0` inside, `+inf` elsewhere (`None` without slices).
fn slice_mask(job: &PlaneJob) -> Option<DepthMap> {
    if job.slices.is_empty() {
        return None;
    }
    let mut mask = DepthMap::for_frame(&job.frame);
    coverage::fill_slices(&mut mask, &job.frame, &job.slices);
    Some(mask)
}

/// Per pixel minimum: what [`coverage::fill_slices`] does to a map (`0` where inside and `d > 0`).
fn merge_mask(map: &mut DepthMap, mask: &DepthMap) {
    for (d, m) in map.depth.iter_mut().zip(&mask.depth) {
        if *m < *d {
            *d = *m;
        }
    }
}

/// A Validation and an OutOfMemory error scope, popped together.
struct ErrorScopes {
    oom: wgpu::ErrorScopeGuard,
    validation: wgpu::ErrorScopeGuard,
}

impl ErrorScopes {
    fn push(device: &wgpu::Device) -> Self {
        let oom = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
        ErrorScopes { oom, validation }
    }

    fn check(self) -> Result<(), BackendError> {
        let validation = pollster::block_on(self.validation.pop());
        let oom = pollster::block_on(self.oom.pop());
        match (oom, validation) {
            (Some(e), _) => Err(BackendError::Device(format!("out of GPU memory: {e}"))),
            (None, Some(e)) => Err(BackendError::Device(format!("GPU validation error: {e}"))),
            (None, None) => Ok(()),
        }
    }
}

impl RasterBackend for GpuBackend {
    fn stats_summary(&self, cells: usize) -> Option<String> {
        let t = self.total_stats();
        let n = cells.max(1) as f64;
        Some(format!(
            "per cell: {:.1} passes, {:.1} draws, {:.1} submissions, {:.0} occluders ({:.0} triangles) drawn, {:.0} KB uploaded, {:.0} KB read back; GPU section {:.1} ms, CPU setup {:.1} ms",
            t.passes as f64 / n,
            t.draws as f64 / n,
            t.submissions as f64 / n,
            t.occluders as f64 / n,
            t.triangles as f64 / n,
            t.bytes_uploaded as f64 / n / 1024.0,
            t.bytes_read_back as f64 / n / 1024.0,
            t.gpu.as_secs_f64() * 1e3 / n,
            t.setup.as_secs_f64() * 1e3 / n,
        ))
    }

    fn name(&self) -> &'static str {
        "gpu"
    }

    fn adapter(&self) -> Option<String> {
        Some(self.adapter_name.clone())
    }

    fn render(&self, jobs: &[PlaneJob]) -> Result<Vec<DepthMap>, BackendError> {
        self.check_failure()?;
        // Records pack pixel origins into 16 bits each.
        let max = self.max_texture.min(1 << 15);
        let fits = |w: u32, h: u32| (1..=max).contains(&w) && (1..=max).contains(&h);
        for job in jobs {
            let (w, h) = (job.frame.width, job.frame.height);
            if !fits(w, h) {
                return Err(BackendError::Device(format!(
                    "plane size {w} × {h} is outside 1..={max} per side supported by {}",
                    self.adapter_name
                )));
            }
            for rp in &job.reproject {
                let (sw, sh) = (rp.source.width, rp.source.height);
                if !fits(sw, sh)
                    || rp.source.depth.len() != sw as usize * sh as usize
                    || rp.cols.len() != w as usize
                    || rp.rows.len() != h as usize
                {
                    return Err(BackendError::Device(format!(
                        "a reprojection onto a {w} × {h} plane has a {sw} × {sh} source with {} \
                         pixels, {} column and {} row windows",
                        rp.source.depth.len(),
                        rp.cols.len(),
                        rp.rows.len()
                    )));
                }
            }
        }
        let t0 = Instant::now();
        let mut stats = RenderStats {
            planes: jobs.len(),
            ..RenderStats::default()
        };
        // CPU setup outside the lock: other threads may render concurrently.
        let prepared: Vec<Prepared> = jobs
            .par_iter()
            .map(|j| self.prepare(j))
            .collect::<Result<_, _>>()?;
        stats.setup = t0.elapsed();
        let mut out: Vec<Option<DepthMap>> = vec![None; jobs.len()];
        // Planes nothing covers and no reprojection sets skip the GPU.
        let mut gpu_jobs = Vec::new();
        for (j, p) in prepared.iter().enumerate() {
            if p.out.vertices.is_empty() && p.sweeps.is_empty() {
                let mut map = DepthMap::for_frame(&jobs[j].frame);
                if let Some(mask) = &p.mask {
                    merge_mask(&mut map, mask);
                }
                out[j] = Some(map);
            } else {
                gpu_jobs.push(j);
            }
        }
        // Submissions bounded in memory.
        let data_budget = DATA_BUDGET.min(self.max_buffer);
        let mut waves: Vec<Vec<usize>> = Vec::new();
        let (mut tgt, mut data) = (0u64, 0u64);
        for &j in &gpu_jobs {
            let (w, h) = (jobs[j].frame.width as u64, jobs[j].frame.height as u64);
            let p = &prepared[j];
            // Target and read-back, plus every reprojection's table (4 bytes a pixel).
            let tables: u64 = p
                .sweeps
                .iter()
                .map(|sw| sw.source_size.0 as u64 * sw.source_size.1 as u64 * 4)
                .sum();
            let t = w * h * 4 + (w * 4).next_multiple_of(256) * h + tables;
            let windows: u64 = p
                .sweeps
                .iter()
                .map(|sw| (sw.words.len() as u64 * 8).next_multiple_of(self.storage_align))
                .sum();
            let d = p.out.vertices.len() as u64 * std::mem::size_of::<Vertex>() as u64
                + p.out.data.len() as u64 * 16
                + p.chunks.len() as u64 * self.storage_align
                + windows;
            match waves.last_mut() {
                Some(w) if tgt + t <= TARGET_BUDGET && data + d <= data_budget => {
                    w.push(j);
                    tgt += t;
                    data += d;
                }
                _ => {
                    waves.push(vec![j]);
                    tgt = t;
                    data = d;
                }
            }
        }
        stats.gpu_planes = gpu_jobs.len();
        if !waves.is_empty() {
            let mut pool = self.pool.lock().unwrap_or_else(|e| e.into_inner());
            let t1 = Instant::now();
            for wave in &waves {
                self.render_wave(&mut pool, jobs, &prepared, wave, &mut out, &mut stats)?;
            }
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
