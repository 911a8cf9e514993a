//! The shrunk-occluder sampler's hemicube on the GPU (`shaders/sampler_setup.wgsl`,
//! `shaders/sampler.wgsl`, `shaders/sampler_fill.wgsl`), the twin of the CPU's [`Hemicube`]:
//! [`GpuSampler`].
//!
//! # Design
//! The occluder polygons are uploaded once ([`GpuSamplerScene::new`]), in Morton order of
//! their centres and cut into clusters of 32 (`CLUSTER`) with their boxes, with the pipelines;
//! each thread renders with its own [`GpuSampler`] (its maps and per-render buffers). Per
//! sample point the CPU only sets up the render ([`Hemicube::begin`]: which pixels and tiles
//! the boxes need) and cuts the boxes into per-view parts ([`Hemicube::box_rects`]); one
//! submission then does the rest: a compute pass repeats the CPU's per-polygon work for the
//! polygons (edges, shrinks, depth, the pixels of its shrunk silhouette per view) and appends
//! draws per view; the fill ([`SamplerFill`]) gives each sub-pixel of a view at 8× its
//! resolution its nearest depth; a compute pass takes each pixel's largest sub-pixel depth; a
//! compute pass tests the boxes' parts, one workgroup each. Only a flag per box and the draw
//! counts are read back.
//!
//! **Rounds** ([`GpuSampler::set_culling`], on by default with the compute fill): the CPU's
//! traversal draws front to back and skips whole BVH nodes behind what it has drawn; the
//! device does the same in eight rounds (`ROUNDS`). The first sets up the nearest clusters
//! (`ROUND_SHARES`); after each round's fill and reduction, a compute pass (`cull` in
//! `shaders/sampler_setup.wgsl`) takes the next shell of clusters by distance, keeps those
//! whose box can still lower a needed pixel and culls the rest for good, appending the kept
//! ones to the round's list; the round's set-up runs over that list alone (an indirect
//! dispatch) and also leaves out each polygon whose shrunk silhouette's pixels are all
//! already covered nearer; the fill then draws only the round's new draws. Depths only come
//! nearer, so what is left out could change no test: the answers are those of one round
//! (`tests/gpu_sampler.rs`), for a fraction of the draws. On lavapipe, random points of the
//! fine forest's 4×2×4 cell at ε 0.05 (`examples/sampler_gpu.rs … cull`): 562 k draws per
//! point down to 95 k at 512 pixels (4.67 s to 1.91 s per point) and to 75 k at 1,024 (8.02
//! to 4.16 s); the coarse forest's cell at ε 0.118 and 256 pixels: 462 k to 20 k (4.61 s to
//! 0.58 s); a whole bake of a 300-tree coarse forest's 1-unit cell (54 points) 150 s to 52 s
//! with the same PVS. The reduction reads a pixel's sub-pixels only until one reaches the
//! pixel's whole-pixel depth, and only the needed pixels.
//!
//! The fill is compute passes where the device has [`wgpu::Features::TEXTURE_ATOMIC`]
//! ([`SamplerFill::Compute`]: one workgroup per draw, one invocation per pixel, which tests the
//! pixel's corners once, computes its 64 sub-pixel bits together when it is partly covered,
//! and lowers `R32Uint` texels holding `f32` bits with `textureAtomicMin`), else render passes
//! ([`SamplerFill::Render`]: one per view, drawn indirectly, one fragment per sub-pixel that
//! repeats the pixel's corner tests, `Min` blended into `R32Float` layers). The two leave the
//! same depths. Measured on an H200 (`examples/sampler_gpu.rs`, 12 random points of the fine
//! forest's middle 4×2×4 cell's faces, ε 0.05): the compute fill takes 45.8 ms per point at
//! 512 pixels and 159.5 at 1,024, the render fill 303.3 and 843.4, with the same objects
//! hidden from every point (an H200 runs graphics work on few of its units; the render fill
//! also repeats each pixel's corner tests 64 times).
//!
//! Where the device has [`wgpu::Features::TIMESTAMP_QUERY`] each pass but the compute fill's
//! clears is timed on the GPU, by phase ([`GpuSampler::gpu_times`], printed by
//! `examples/sampler_gpu.rs`).
//!
//! # Why it is conservative, and what it answers
//! The passes repeat the CPU's expressions (`f64` where the CPU uses `f64`, its `f32` corner
//! tests with its table of `√(u²+v²+1)` and margin, its roundings up), so a sub-pixel is
//! covered only where the CPU's argument ([`crate::sampler`]) covers it. Each sub-pixel keeps
//! its own nearest depth, as the CPU's layers do (it spills layers past eight instead of
//! merging them), so both hide the same boxes: from two points of the fine forest's cell at
//! ε 0.05 and 512 px, 3,889 objects each with no disagreement (`examples/sampler_gpu.rs`;
//! before the CPU stopped merging, it hid 3,789). A driver
//! rounding an `f64` operation differently (a fused multiply-add) moves a decision only where
//! a test is within a rounding error of a margin 10⁷ times larger. The GPU leaves out polygons
//! of more than eight vertices and textured card triangles, which only uncovers pixels.
//!
//! # Use
//! `bake::sampling` renders with it on the GPU backend (one [`GpuSampler`] per thread): per
//! band of a rectangle, the objects' boxes, then the open ones' pieces, then the open pieces'
//! triangles, each a submission on the same maps. The scene's triangles go up once per bake
//! where they fit in a storage binding ([`GpuSamplerScene::upload_triangles`], nine `f32`
//! each: scene vertices are `f32`, so the shader's `f64` of them is exact), and a triangle
//! test sends each triangle's index, 8 bytes, instead of its corners, 72
//! ([`GpuSampler::test_scene_triangles`]; [`GpuSampler::test_triangles`] takes corners).
//!
//! # Not yet
//! Several sample points per submission; one submission per band (the open boxes' pieces and
//! the open pieces' triangles compacted on the device); rounds with the render fill (it draws
//! each view's list once); the rounds measured on a real GPU.

use super::GpuBackend;
use super::device::ErrorScopes;
use crate::backend::BackendError;
use crate::geom::DAabb;
use crate::sampler::{BoxRect, Hemicube, SampleOccluders};
use glam::{DVec3, Vec3};
use std::num::NonZeroU64;

/// Bytes of one parameter slot (WebGPU's largest uniform offset alignment).
const PARAM_SLOT: u64 = 256;
/// Parameter slots: the five views' fills, the reduction, the boxes' test, the triangles',
/// then one per round for its set-up's dispatch (`setup_args` in `shaders/sampler_fill.wgsl`).
const SLOTS: u64 = 8 + ROUNDS as u64;
/// Bytes of one draw (two `vec4<u32>`).
const DRAW_BYTES: u64 = 32;
/// Workgroup size of the compute entry points.
const WORKGROUP: u32 = 64;
/// The most workgroups along one dimension of a dispatch.
const MAX_GROUPS: u32 = 65535;
/// Sub-pixels per pixel side.
const SUB: u32 = 8;
/// Polygons per cluster of the rounds' culling (`CLUSTER` in
/// `shaders/sampler_setup.wgsl`).
const CLUSTER: u32 = 32;
/// A round's parameters (`Round` in `shaders/sampler_setup.wgsl`): its number, its farthest
/// cluster distance (`f32` bits), where the pixels' depths start in the edges' buffer (in
/// 16-byte units), where the clusters' boxes start in the points (in `f64`s), the clusters,
/// its list of clusters.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct RoundParams {
    round: u32,
    limit: u32,
    pix: u32,
    boxes: u32,
    clusters: u32,
    /// Where the round's list of clusters starts in the indirect buffer (words; `u32::MAX`:
    /// no list, the set-up runs over every polygon), and the word of its length.
    list: u32,
    count: u32,
    pad: u32,
}

/// Bytes of [`RoundParams`].
const ROUND_BYTES: u64 = std::mem::size_of::<RoundParams>() as u64;
/// The alignment of the pixels' depths in the edges' buffer (WebGPU's largest storage offset
/// alignment: the tests bind them at that offset).
const PIX_ALIGN: u64 = 256;

/// Rounds of a render ([`GpuSampler::set_culling`]).
const ROUNDS: usize = 8;
/// The share of the clusters, nearest first, that the rounds up to each take (the first
/// draws all of its share; each later one only those of its shell that the depths drawn so
/// far do not hide).
const ROUND_SHARES: [f64; ROUNDS] = [
    1.0 / 64.0,
    1.0 / 32.0,
    1.0 / 16.0,
    0.125,
    0.25,
    0.4,
    0.6,
    1.0,
];
/// The fewest clusters for rounds (with fewer, one round draws them all).
const ROUNDS_MIN: usize = 64;

/// Where the rounds' words lie in a sampler's indirect buffer (`u32` indices): the five
/// indirect draws (20 words), then per cluster its state, per round its list's length, per
/// round its list (room for every cluster).
#[derive(Clone, Copy, Debug)]
struct Layout {
    clusters: u32,
    counts: u32,
    lists: u32,
    end: u32,
}

impl Layout {
    fn new(clusters: usize) -> Self {
        let c = clusters.max(1) as u32;
        let counts = 20 + c;
        let lists = counts + ROUNDS as u32;
        Layout {
            clusters: c,
            counts,
            lists,
            end: lists + ROUNDS as u32 * c,
        }
    }

    /// Round `r`'s list (0 the first).
    fn list(&self, r: usize) -> u32 {
        self.lists + r as u32 * self.clusters
    }
}

/// The least `f32` no less than `x`.
fn f32_up(x: f64) -> f32 {
    let f = x as f32;
    if f64::from(f) < x { f.next_up() } else { f }
}

/// Per cluster of `clusters` its state when a render begins (with `rounds`: 1 for those the
/// first round draws, the nearest [`ROUND_SHARES`]`[0]` of them, ties at the cut included,
/// and 0 for the rest; without, 1 for all), and each round's farthest cluster distance
/// (rounded up to `f32`; the last infinite).
fn round_states(clusters: &[DAabb], eye: DVec3, rounds: bool) -> (Vec<u32>, [f32; ROUNDS]) {
    let mut limits = [f32::INFINITY; ROUNDS];
    if !rounds {
        return (vec![1; clusters.len().max(1)], limits);
    }
    let dist: Vec<f64> = clusters.iter().map(|b| b.distance_to(eye)).collect();
    // Each share's quantile, largest first: after a selection the smaller ones lie before it
    // (no full sort per render).
    let mut order = dist.clone();
    let mut end = order.len();
    for r in (0..ROUNDS - 1).rev() {
        let n = ((clusters.len() as f64 * ROUND_SHARES[r]) as usize).clamp(1, end);
        let (_, &mut nth, _) = order[..end].select_nth_unstable_by(n - 1, f64::total_cmp);
        limits[r] = f32_up(nth);
        end = n;
    }
    let states = dist
        .iter()
        .map(|&d| u32::from(d <= f64::from(limits[0])))
        .collect();
    (states, limits)
}

/// The indices of `bounds` in Morton (Z-curve) order of their centres over the boxes' whole
/// extent, 21 bits per axis: consecutive polygons lie close together, so clusters of them
/// have small boxes.
fn morton_order(bounds: &[DAabb]) -> Vec<usize> {
    let mut all = DAabb::EMPTY;
    for b in bounds {
        all.grow(b.min);
        all.grow(b.max);
    }
    let (lo, hi) = (all.min, all.max);
    let scale = ((1u64 << 21) - 1) as f64 / (hi - lo).max_element().max(f64::MIN_POSITIVE);
    let spread = |x: u64| {
        let mut x = x & 0x1f_ffff;
        x = (x | x << 32) & 0x1f_0000_0000_ffff;
        x = (x | x << 16) & 0x1f_0000_ff00_00ff;
        x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
        x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
        (x | x << 2) & 0x1249_2492_4924_9249
    };
    let mut keyed: Vec<(u64, usize)> = bounds
        .iter()
        .enumerate()
        .map(|(k, b)| {
            let c = ((b.min + b.max) * 0.5 - lo) * scale;
            let q = |t: f64| if t.is_finite() { t.max(0.0) as u64 } else { 0 };
            (
                spread(q(c.x)) | spread(q(c.y)) << 1 | spread(q(c.z)) << 2,
                k,
            )
        })
        .collect();
    keyed.sort_unstable();
    keyed.into_iter().map(|(_, k)| k).collect()
}

/// Timestamp pairs one submission writes at most: the render fill's set-up, five fill passes,
/// reduction and two tests; the compute fill's rounds of set-up, two fill passes and
/// reduction, the culls between them and two tests (its clears are not timed).
const STAMP_PAIRS: usize = 48;
/// Bytes between resolved timestamp pairs (`wgpu::QUERY_RESOLVE_BUFFER_ALIGNMENT`).
const STAMP_STRIDE: u64 = wgpu::QUERY_RESOLVE_BUFFER_ALIGNMENT;

/// GPU time of a [`GpuSampler`]'s passes by phase, from the device's timestamps, summed over
/// its submissions since it was made (all zero without [`wgpu::Features::TIMESTAMP_QUERY`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SamplerTimes {
    /// The set-up passes (the polygons' edges, shrinks, depth and draws).
    pub setup: std::time::Duration,
    /// The fill (its compute passes or render passes; not the compute fill's clears).
    pub fill: std::time::Duration,
    /// The pixels' largest sub-pixel depths.
    pub reduce: std::time::Duration,
    /// The tests of box parts and triangles.
    pub tests: std::time::Duration,
    /// The later rounds' choice of clusters ([`GpuSampler::set_culling`]).
    pub cull: std::time::Duration,
    /// Passes timed.
    pub passes: usize,
}

/// A sampler's query set and the buffer its pairs are resolved into.
struct Stamps {
    set: wgpu::QuerySet,
    resolved: wgpu::Buffer,
}

/// The uniforms of one pass (`Params` of the shader).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    res: u32,
    view: u32,
    subpixel: u32,
    n: u32,
    rows: u32,
    groups_x: u32,
    axis: u32,
    sign: u32,
    base: u32,
    /// The triangle test reads scene triangles by index (1) or inline (0).
    tri_ids: u32,
    pad: [u32; 2],
}

/// A compute pass's timestamp writes: the pair at `i` of the query set, if any.
fn compute_writes(
    p: Option<(&wgpu::QuerySet, u32)>,
) -> Option<wgpu::ComputePassTimestampWrites<'_>> {
    p.map(|(query_set, i)| wgpu::ComputePassTimestampWrites {
        query_set,
        beginning_of_pass_write_index: Some(i),
        end_of_pass_write_index: Some(i + 1),
    })
}

/// The dispatch size for `groups` workgroups: `(x, y)` with `x ≤ 65535`.
fn dispatch(groups: u32) -> (u32, u32) {
    let x = groups.clamp(1, MAX_GROUPS);
    (x, groups.div_ceil(MAX_GROUPS).max(1))
}

/// How the sampler fills its sub-pixel depths (module docs). Both leave the same depths, so
/// the same answers (`tests/gpu_sampler.rs` compares them); the compute fill does a pixel's
/// work once where the render fill repeats it for each of its 64 sub-pixels, and runs on all of
/// a GPU's compute units (on an H200 graphics work runs on few of them).
///
/// ```
/// use umbrasweep::backend::gpu::sampler::SamplerFill;
/// assert_eq!("compute".parse::<SamplerFill>(), Ok(SamplerFill::Compute));
/// assert_eq!(SamplerFill::Render.to_string(), "render");
/// assert!("blend".parse::<SamplerFill>().is_err());
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SamplerFill {
    /// Compute passes, one invocation per pixel of a draw, lowering `R32Uint` layers with
    /// `textureAtomicMin` (`shaders/sampler_fill.wgsl`). Needs
    /// [`wgpu::Features::TEXTURE_ATOMIC`] (Vulkan, DX12, Metal 3.1).
    Compute,
    /// Render passes, one fragment per sub-pixel, `Min` blended into `R32Float` layers
    /// (`vs_fill` / `fs_fill` of `shaders/sampler.wgsl`).
    Render,
}

impl std::fmt::Display for SamplerFill {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            SamplerFill::Compute => "compute",
            SamplerFill::Render => "render",
        })
    }
}

impl std::str::FromStr for SamplerFill {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "compute" => Ok(SamplerFill::Compute),
            "render" => Ok(SamplerFill::Render),
            _ => Err(format!("unknown sampler fill {s:?} (compute or render)")),
        }
    }
}

/// The fill's pipelines of a [`GpuSamplerScene`].
enum FillPipelines {
    Render {
        layout: wgpu::BindGroupLayout,
        pipeline: wgpu::RenderPipeline,
    },
    Compute {
        layout: wgpu::BindGroupLayout,
        args_layout: wgpu::BindGroupLayout,
        args: wgpu::ComputePipeline,
        /// A later round's set-up dispatch from its list's length.
        setup_args: wgpu::ComputePipeline,
        fill: wgpu::ComputePipeline,
    },
}

/// A [`GpuSampler`]'s sub-pixel depths: per view a layer of `8R × 8R` (the sides use the
/// lower half), and for the compute fill also a layer of `R × R` of covered pixels.
enum Maps {
    Render {
        _fine: wgpu::Texture,
        layers: Vec<wgpu::TextureView>,
        all: wgpu::TextureView,
    },
    Compute {
        _fine: wgpu::Texture,
        _full: wgpu::Texture,
        /// The fine layers, then the full ones (each cleared by a render pass).
        layers: Vec<wgpu::TextureView>,
        fine_all: wgpu::TextureView,
        full_all: wgpu::TextureView,
        /// Per view an indirect dispatch (`fill_args`).
        args: wgpu::Buffer,
    },
}

/// The sampler's hemicube on a [`GpuBackend`]'s device, rendering a [`GpuSamplerScene`]'s
/// polygons (module docs).
///
/// ```no_run
/// use glam::DVec3;
/// use umbrasweep::backend::gpu::GpuBackend;
/// use umbrasweep::backend::gpu::sampler::{GpuSampler, GpuSamplerScene};
/// use umbrasweep::geom::DAabb;
/// use umbrasweep::sampler::SampleOccluders;
///
/// let gpu = GpuBackend::new()?;
/// let leaf = vec![DVec3::new(-1.0, -1.0, 5.0), DVec3::new(1.0, -1.0, 5.0), DVec3::new(0.0, 1.0, 5.0)];
/// let occ = SampleOccluders::from_polygons(&[(leaf, 0)]);
/// let boxes = [DAabb { min: DVec3::new(-0.1, -0.1, 9.0), max: DVec3::new(0.1, 0.1, 9.2) }];
/// let scene = GpuSamplerScene::new(&gpu, &occ)?;
/// let mut hc = GpuSampler::new(&gpu, &scene, 64)?;
/// hc.begin(DVec3::ZERO, 2, 1.0, 0.01, &boxes);
/// assert_eq!(hc.test_boxes(&boxes)?, vec![true]);
/// # Ok::<(), umbrasweep::backend::BackendError>(())
/// ```
pub struct GpuSampler<'a> {
    gpu: &'a GpuBackend,
    scene: &'a GpuSamplerScene,
    hc: Hemicube,
    maps: Maps,
    params: wgpu::Buffer,
    norms: wgpu::Buffer,
    /// Per point: the set-up pass's output.
    draws: wgpu::Buffer,
    pedges: wgpu::Buffer,
    pplanes: wgpu::Buffer,
    indirect: wgpu::Buffer,
    frame: Option<wgpu::Buffer>,
    frame_u: Option<wgpu::Buffer>,
    parts_u: Option<wgpu::Buffer>,
    parts_f: Option<wgpu::Buffer>,
    flags: Option<wgpu::Buffer>,
    staging: Option<wgpu::Buffer>,
    tris: Option<wgpu::Buffer>,
    tflags: Option<wgpu::Buffer>,
    last_draws: u64,
    /// Of them, the first round's.
    last_first_round: u64,
    /// Each round's parameters ([`RoundParams`], a slot each), the draw counts when each
    /// round begins (zeros for the first, copied from the counts for the others).
    round_params: wgpu::Buffer,
    firsts: [wgpu::Buffer; ROUNDS],
    /// Where the pixels' largest sub-pixel depths start in `pedges` (bytes).
    pix_off: u64,
    /// Whether renders draw in rounds, each after the first culled by the depths before it.
    culling: bool,
    /// The polygons are drawn for the last `begin` (tests after the first reuse the maps).
    rendered: bool,
    /// Timestamps, where the device has `TIMESTAMP_QUERY`.
    stamps: Option<Stamps>,
    times: SamplerTimes,
}

/// One scene's occluder polygons on the device, with the sampler's pipelines: made once and
/// shared by the [`GpuSampler`]s that render from it (one per thread, each with its own maps).
pub struct GpuSamplerScene {
    polys: u32,
    /// Draws each view's region of a sampler's draws holds.
    cap: u32,
    points_len: u64,
    setup_layout: wgpu::BindGroupLayout,
    test_layout: wgpu::BindGroupLayout,
    setup: wgpu::ComputePipeline,
    fill: FillPipelines,
    reduce: wgpu::ComputePipeline,
    test: wgpu::ComputePipeline,
    test_tri: wgpu::ComputePipeline,
    /// The later rounds' choice of clusters (`cull` in `shaders/sampler_setup.wgsl`).
    cull: wgpu::ComputePipeline,
    /// The polygons (first point, end, card) in Morton order and their points (`f64`, then
    /// the clusters' boxes), uploaded once.
    poly_buf: wgpu::Buffer,
    points: wgpu::Buffer,
    /// The boxes of the clusters of [`CLUSTER`] consecutive uploaded polygons (on the device
    /// after the points).
    clusters: Vec<DAabb>,
    /// The occludees' triangles (nine `f32` each), uploaded once when they fit
    /// ([`GpuSamplerScene::upload_triangles`]); else a 16-byte stand-in.
    triangles: wgpu::Buffer,
    /// How many `triangles` holds (0: none uploaded).
    triangle_count: u32,
}

impl std::fmt::Debug for GpuSamplerScene {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuSamplerScene")
            .field("polygons", &self.polys)
            .finish_non_exhaustive()
    }
}

impl std::fmt::Debug for GpuSampler<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuSampler")
            .field("resolution", &self.hc.resolution())
            .finish_non_exhaustive()
    }
}

/// A bind group entry for the whole of `buffer`.
fn entry(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry {
        binding,
        resource: buffer.as_entire_binding(),
    }
}

/// The largest storage binding of `gpu`'s device.
fn max_binding(gpu: &GpuBackend) -> u64 {
    gpu.limits
        .max_buffer
        .min(gpu.device.limits().max_storage_buffer_binding_size)
}

/// A storage buffer of `size` bytes (at least 16), labelled.
fn storage_buffer(
    gpu: &GpuBackend,
    size: u64,
    extra: wgpu::BufferUsages,
    label: &'static str,
) -> Result<wgpu::Buffer, BackendError> {
    let size = size.max(16).next_multiple_of(16);
    let max = max_binding(gpu);
    if size > max {
        return Err(BackendError::BufferTooLarge { label, size, max });
    }
    Ok(gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | extra,
        mapped_at_creation: false,
    }))
}

/// Bytes of one polygon point in its storage binding (three `f64`): the scene's largest.
const POINT_BYTES: u64 = 24;

/// Device memory the GPU samplers of one bake may take together unless
/// [`GpuBackend::set_sampler_memory`] says otherwise: 4 GiB, so that sixteen threads do not ask
/// a consumer GPU for 28 GB.
pub const DEFAULT_SAMPLER_MEMORY: u64 = 4 << 30;

/// Bytes of one resident occludee triangle (nine `f32`: scene vertices are `f32`, so the
/// shader's `f64` of them is the CPU's exactly).
pub const TRIANGLE_BYTES: u64 = 36;

/// The most bytes [`GpuSamplerScene::upload_triangles`] stages at once (a multiple of
/// [`TRIANGLE_BYTES`], 4.5 MiB): the paper-size forest's 7.9 M triangles take 285 MB on the
/// device and never a whole copy on the CPU.
pub const UPLOAD_CHUNK: u64 = 36 << 17;

impl GpuSamplerScene {
    /// Why the sampler cannot render `occ` on `gpu`'s device, or `None` when it can: the
    /// device lacks `SHADER_F64`, or the polygons' points (24 bytes each in one storage
    /// binding) exceed its largest storage binding. A bake then samples on the CPU, with the
    /// same answers (see the module docs), and its summary says why. A device that takes the
    /// polygons but not one level's textures (`GpuSampler::new` fails) samples that level
    /// on the CPU (`CullerWork::cpu_fallback` says why).
    pub fn refusal(gpu: &GpuBackend, occ: &SampleOccluders) -> Option<String> {
        if !gpu.sampler_on_gpu() {
            return Some("the device has no SHADER_F64".to_string());
        }
        let clusters = occ.polys.len().div_ceil(CLUSTER as usize) as u64;
        let need = POINT_BYTES * occ.points.len() as u64 + 2 * POINT_BYTES * clusters;
        let max = max_binding(gpu);
        let size = |b: u64| match b >> 20 {
            0 => format!("{} KiB", b.div_ceil(1 << 10)),
            m => format!("{m} MiB"),
        };
        (need > max).then(|| {
            format!(
                "the occluders' {} polygon points need {} in one storage binding, more than the \
                 device's largest ({})",
                occ.points.len(),
                size(need),
                size(max)
            )
        })
    }

    /// The fill of this scene's samplers.
    pub fn fill(&self) -> SamplerFill {
        match self.fill {
            FillPipelines::Render { .. } => SamplerFill::Render,
            FillPipelines::Compute { .. } => SamplerFill::Compute,
        }
    }

    /// The fill [`GpuSamplerScene::new`] uses on `gpu`'s device: [`SamplerFill::Compute`]
    /// where the device has [`wgpu::Features::TEXTURE_ATOMIC`] (the backend's own device takes
    /// it whenever the adapter has it), else [`SamplerFill::Render`].
    pub fn default_fill(gpu: &GpuBackend) -> SamplerFill {
        if gpu
            .device
            .features()
            .contains(wgpu::Features::TEXTURE_ATOMIC)
        {
            SamplerFill::Compute
        } else {
            SamplerFill::Render
        }
    }

    /// The polygons of `occ` uploaded to `gpu`'s device, and the sampler's pipelines with
    /// [`GpuSamplerScene::default_fill`].
    ///
    /// # Errors
    /// * [`BackendError::MissingFeatures`] when the device lacks `SHADER_F64` (the set-up,
    ///   sub-pixel masks and plane depths are the CPU's `f64` expressions);
    /// * [`BackendError::BufferTooLarge`] when the polygons' points exceed the device's largest
    ///   storage binding (24 bytes per point; [`GpuSamplerScene::refusal`] says so first);
    /// * [`BackendError::Validation`] or [`BackendError::OutOfMemory`] when the device reports
    ///   one while the pipelines and buffers are created.
    pub fn new(gpu: &GpuBackend, occ: &SampleOccluders) -> Result<Self, BackendError> {
        Self::with_fill(gpu, occ, Self::default_fill(gpu))
    }

    /// As [`GpuSamplerScene::new`] with the given fill.
    ///
    /// # Errors
    /// As [`GpuSamplerScene::new`], and [`BackendError::MissingFeatures`] for
    /// [`SamplerFill::Compute`] on a device without [`wgpu::Features::TEXTURE_ATOMIC`].
    pub fn with_fill(
        gpu: &GpuBackend,
        occ: &SampleOccluders,
        fill: SamplerFill,
    ) -> Result<Self, BackendError> {
        gpu.check_failure()?;
        let device = &gpu.device;
        let mut needs = wgpu::Features::SHADER_F64;
        if fill == SamplerFill::Compute {
            needs |= wgpu::Features::TEXTURE_ATOMIC;
        }
        if !device.features().contains(needs) {
            return Err(BackendError::MissingFeatures {
                missing: needs - device.features(),
            });
        }
        let n = occ.polys.len();
        // The polygons in Morton order of their boxes' centres, cut into clusters of
        // `CLUSTER` (the rounds' unit of culling).
        let bounds: Vec<DAabb> = (0..n).map(|k| occ.poly_bounds(k)).collect();
        let order = morton_order(&bounds);
        let mut poly_words: Vec<[u32; 4]> = Vec::with_capacity(n);
        for &k in &order {
            let p = &occ.polys[k];
            poly_words.push([p.start, p.end, u32::from(occ.card(k).is_some()), 0]);
        }
        let clusters: Vec<DAabb> = order
            .chunks(CLUSTER as usize)
            .map(|ks| {
                let mut b = DAabb::EMPTY;
                for &k in ks {
                    b.grow(bounds[k].min);
                    b.grow(bounds[k].max);
                }
                b
            })
            .collect();
        // The points, then the clusters' boxes (min, max).
        let point_data: Vec<f64> = occ
            .points
            .iter()
            .flat_map(|p| p.to_array())
            .chain(
                clusters
                    .iter()
                    .flat_map(|b| b.min.to_array().into_iter().chain(b.max.to_array())),
            )
            .collect();
        let np = n as u64;
        // Each polygon draws at most once per view; a view's share of the largest binding caps
        // its draws (overflowing it is an error, see `GpuSampler::test_boxes`).
        let cap = np.clamp(1, max_binding(gpu) / (5 * DRAW_BYTES)) as u32;
        let scope = ErrorScopes::push(device);
        let poly_buf = storage_buffer(
            gpu,
            16 * np,
            wgpu::BufferUsages::empty(),
            "sampler polygons",
        )?;
        let points = storage_buffer(
            gpu,
            8 * point_data.len() as u64,
            wgpu::BufferUsages::empty(),
            "sampler polygon points",
        )?;
        gpu.queue
            .write_buffer(&poly_buf, 0, bytemuck::cast_slice(&poly_words));
        gpu.queue
            .write_buffer(&points, 0, bytemuck::cast_slice(&point_data));
        let setup_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("shaders/sampler_setup.wgsl"),
            source: wgpu::ShaderSource::Wgsl(super::SAMPLER_SETUP_WGSL.into()),
        });
        let (label, source) = match fill {
            SamplerFill::Render => ("shaders/sampler.wgsl", super::SAMPLER_WGSL),
            SamplerFill::Compute => ("shaders/sampler_fill.wgsl", super::SAMPLER_FILL_WGSL),
        };
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let uniform = |visibility| wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: true,
                min_binding_size: NonZeroU64::new(std::mem::size_of::<Params>() as u64),
            },
            count: None,
        };
        let storage = |binding, visibility, read_only| wgpu::BindGroupLayoutEntry {
            binding,
            visibility,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let cs = wgpu::ShaderStages::COMPUTE;
        let setup_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("sampler set-up bind group layout"),
            entries: &[
                storage(0, cs, true),
                storage(1, cs, true),
                storage(2, cs, true),
                storage(3, cs, true),
                storage(4, cs, false),
                storage(5, cs, false),
                storage(6, cs, false),
                storage(7, cs, false),
                wgpu::BindGroupLayoutEntry {
                    binding: 9,
                    visibility: cs,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: true,
                        min_binding_size: NonZeroU64::new(ROUND_BYTES),
                    },
                    count: None,
                },
            ],
        });
        let texture = |binding, sample_type| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: cs,
            ty: wgpu::BindingType::Texture {
                sample_type,
                view_dimension: wgpu::TextureViewDimension::D2Array,
                multisampled: false,
            },
            count: None,
        };
        let atomic = |binding| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: cs,
            ty: wgpu::BindingType::StorageTexture {
                access: wgpu::StorageTextureAccess::Atomic,
                format: wgpu::TextureFormat::R32Uint,
                view_dimension: wgpu::TextureViewDimension::D2Array,
            },
            count: None,
        };
        let mut test_entries = vec![
            uniform(cs),
            storage(6, cs, false),
            storage(7, cs, true),
            storage(8, cs, true),
            storage(9, cs, false),
            storage(10, cs, true),
            storage(11, cs, false),
            storage(12, cs, true),
            storage(19, cs, true),
        ];
        match fill {
            SamplerFill::Render => test_entries.push(texture(
                5,
                wgpu::TextureSampleType::Float { filterable: false },
            )),
            SamplerFill::Compute => test_entries.extend([
                texture(5, wgpu::TextureSampleType::Uint),
                texture(13, wgpu::TextureSampleType::Uint),
            ]),
        }
        let test_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("sampler test bind group layout"),
            entries: &test_entries,
        });
        let layout = |label: &'static str, bgl: &wgpu::BindGroupLayout| {
            device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(label),
                bind_group_layouts: &[Some(bgl)],
                immediate_size: 0,
            })
        };
        let setup_pl = layout("sampler set-up pipeline layout", &setup_layout);
        let test_pl = layout("sampler test pipeline layout", &test_layout);
        // The set-up module's entry points share its layout.
        let from_setup = |entry: &'static str, label: &'static str| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(label),
                layout: Some(&setup_pl),
                module: &setup_module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let setup = from_setup("setup", "sampler set-up pipeline");
        let cull = from_setup("cull", "sampler cluster cull pipeline");
        let compute_with = |entry: &'static str, label: &'static str, pl: &wgpu::PipelineLayout| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(label),
                layout: Some(pl),
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let compute = |entry, label| compute_with(entry, label, &test_pl);
        let fill = match fill {
            SamplerFill::Render => {
                let vf = wgpu::ShaderStages::VERTEX_FRAGMENT;
                let bgl = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                    label: Some("sampler fill bind group layout"),
                    entries: &[
                        uniform(vf),
                        storage(1, vf, true),
                        storage(2, vf, true),
                        storage(3, vf, true),
                        storage(4, vf, true),
                    ],
                });
                let pipeline = super::pipelines::depth_map_pipeline(
                    device,
                    "sampler fill",
                    &bgl,
                    &module,
                    ("vs_fill", "fs_fill"),
                    &[],
                );
                FillPipelines::Render {
                    layout: bgl,
                    pipeline,
                }
            }
            SamplerFill::Compute => {
                let bgl = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                    label: Some("sampler compute fill bind group layout"),
                    entries: &[
                        uniform(cs),
                        storage(1, cs, true),
                        storage(2, cs, true),
                        storage(3, cs, true),
                        storage(4, cs, true),
                        storage(14, cs, true),
                        atomic(15),
                        atomic(16),
                        storage(18, cs, true),
                    ],
                });
                // The dispatches apart: a buffer written by a pass cannot be its indirect one.
                let args_layout =
                    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                        label: Some("sampler fill arguments bind group layout"),
                        entries: &[
                            uniform(cs),
                            storage(14, cs, true),
                            storage(17, cs, false),
                            storage(18, cs, true),
                        ],
                    });
                let pl = layout("sampler compute fill pipeline layout", &bgl);
                let args_pl = layout("sampler fill arguments pipeline layout", &args_layout);
                FillPipelines::Compute {
                    args: compute_with("fill_args", "sampler fill arguments pipeline", &args_pl),
                    setup_args: compute_with(
                        "setup_args",
                        "sampler set-up dispatch pipeline",
                        &args_pl,
                    ),
                    fill: compute_with("fill", "sampler compute fill pipeline", &pl),
                    layout: bgl,
                    args_layout,
                }
            }
        };
        let reduce = compute("reduce", "sampler reduce pipeline");
        let test = compute("test", "sampler test pipeline");
        let test_tri = compute("test_tri", "sampler triangle test pipeline");
        scope.check()?;
        Ok(GpuSamplerScene {
            polys: n as u32,
            cap,
            points_len: occ.points.len() as u64,
            setup_layout,
            test_layout,
            setup,
            cull,
            fill,
            reduce,
            test,
            test_tri,
            poly_buf,
            points,
            clusters,
            triangles: storage_buffer(
                gpu,
                16,
                wgpu::BufferUsages::empty(),
                "sampler scene triangles (none)",
            )?,
            triangle_count: 0,
        })
    }
}

impl GpuSamplerScene {
    /// Uploads the occludees' triangles once (the `t`-th item is triangle `t`, scene
    /// coordinates), so that [`GpuSampler::test_scene_triangles`] sends only their indices
    /// (8 bytes a triangle instead of 72). They go up in slices of at most [`UPLOAD_CHUNK`]
    /// bytes, never copied whole. Returns false, keeping none, when they exceed the device's
    /// largest storage binding (36 bytes each): the tests then upload each triangle tested,
    /// with the same answers.
    ///
    /// # Errors
    /// The device's failures ([`BackendError::device_failed`]).
    pub fn upload_triangles<I>(
        &mut self,
        gpu: &GpuBackend,
        triangles: I,
    ) -> Result<bool, BackendError>
    where
        I: IntoIterator<Item = [Vec3; 3]>,
        I::IntoIter: ExactSizeIterator,
    {
        gpu.check_failure()?;
        let triangles = triangles.into_iter();
        let count = triangles.len();
        let size = TRIANGLE_BYTES * count as u64;
        if count == 0 || size.next_multiple_of(16) > max_binding(gpu) || count > u32::MAX as usize {
            return Ok(false);
        }
        let scope = ErrorScopes::push(&gpu.device);
        let buffer = storage_buffer(
            gpu,
            size,
            wgpu::BufferUsages::empty(),
            "sampler scene triangles",
        )?;
        let per_chunk = (UPLOAD_CHUNK / TRIANGLE_BYTES) as usize;
        let mut words: Vec<f32> = Vec::with_capacity(9 * per_chunk.min(count));
        let mut offset = 0u64;
        for t in triangles {
            words.extend(t.iter().flat_map(|v| v.to_array()));
            if words.len() == 9 * per_chunk {
                gpu.queue
                    .write_buffer(&buffer, offset, bytemuck::cast_slice(&words));
                offset += 4 * words.len() as u64;
                words.clear();
            }
        }
        if !words.is_empty() {
            gpu.queue
                .write_buffer(&buffer, offset, bytemuck::cast_slice(&words));
        }
        scope.check()?;
        self.triangles = buffer;
        self.triangle_count = count as u32;
        Ok(true)
    }

    /// How many occludee triangles are on the device ([`GpuSamplerScene::upload_triangles`];
    /// 0 when none).
    pub fn resident_triangles(&self) -> u32 {
        self.triangle_count
    }
}

impl<'a> GpuSampler<'a> {
    /// A hemicube of `res` pixels across each view (rounded up to a multiple of 16, as
    /// [`Hemicube::new`]) rendering `scene`'s polygons on `gpu` (the device `scene` was made
    /// on).
    ///
    /// # Errors
    /// * [`BackendError::PlaneSize`] when `8 × res` exceeds the device's largest texture side;
    /// * [`BackendError::BufferTooLarge`] when a render's buffers exceed the device's largest
    ///   storage binding (about 160 bytes per polygon; the edges' buffer, 16 bytes per point,
    ///   also holds the pixels' depths, 20 bytes per pixel of `res` square);
    /// * [`BackendError::Validation`] or [`BackendError::OutOfMemory`] when the device reports
    ///   one while the maps and buffers are created (five 32-bit layers of `8·res` square:
    ///   1.3 GB at 1,024 pixels; [`GpuSampler::device_bytes`] gives the whole).
    pub fn new(
        gpu: &'a GpuBackend,
        scene: &'a GpuSamplerScene,
        res: u32,
    ) -> Result<Self, BackendError> {
        gpu.check_failure()?;
        let device = &gpu.device;
        let hc = Hemicube::new(res);
        let r = hc.resolution() as u32;
        let side = SUB * r;
        if side > gpu.limits.max_texture {
            return Err(BackendError::PlaneSize {
                width: side,
                height: side,
                max: gpu.limits.max_texture,
                adapter: gpu.adapter_name.clone(),
            });
        }
        let scope = ErrorScopes::push(device);
        let draws = storage_buffer(
            gpu,
            5 * DRAW_BYTES * u64::from(scene.cap),
            wgpu::BufferUsages::empty(),
            "sampler draws",
        )?;
        let r64 = u64::from(hc.resolution() as u32);
        // The edges, then (at a binding offset's alignment) the pixels' largest sub-pixel
        // depths: one storage buffer for both keeps the set-up within eight.
        let pix_off = (16 * scene.points_len).next_multiple_of(PIX_ALIGN);
        let pedges = storage_buffer(
            gpu,
            pix_off + 4 * 5 * r64 * r64,
            wgpu::BufferUsages::empty(),
            "sampler edges and pixel depths",
        )?;
        let pplanes = storage_buffer(
            gpu,
            6 * 8 * u64::from(scene.polys),
            wgpu::BufferUsages::empty(),
            "sampler planes",
        )?;
        // The five indirect draws, then each cluster's state (its round), each round's list
        // length and list ([`Layout`]).
        let indirect = storage_buffer(
            gpu,
            4 * u64::from(Layout::new(scene.clusters.len()).end),
            wgpu::BufferUsages::INDIRECT | wgpu::BufferUsages::COPY_SRC,
            "sampler indirect draws and cluster rounds",
        )?;
        let layers = |label: &'static str, side: u32, format, usage| {
            let texture = device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d {
                    width: side,
                    height: side,
                    depth_or_array_layers: 5,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            });
            let one: Vec<wgpu::TextureView> = (0..5)
                .map(|k| {
                    texture.create_view(&wgpu::TextureViewDescriptor {
                        label: Some(label),
                        dimension: Some(wgpu::TextureViewDimension::D2),
                        base_array_layer: k,
                        array_layer_count: Some(1),
                        ..Default::default()
                    })
                })
                .collect();
            let all = texture.create_view(&wgpu::TextureViewDescriptor {
                label: Some(label),
                dimension: Some(wgpu::TextureViewDimension::D2Array),
                ..Default::default()
            });
            (texture, one, all)
        };
        let maps = match scene.fill {
            FillPipelines::Render { .. } => {
                let (fine, layers, all) = layers(
                    "sampler sub-pixel depths",
                    side,
                    wgpu::TextureFormat::R32Float,
                    wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
                );
                Maps::Render {
                    _fine: fine,
                    layers,
                    all,
                }
            }
            FillPipelines::Compute { .. } => {
                let usage = wgpu::TextureUsages::RENDER_ATTACHMENT
                    | wgpu::TextureUsages::TEXTURE_BINDING
                    | wgpu::TextureUsages::STORAGE_BINDING
                    | wgpu::TextureUsages::STORAGE_ATOMIC;
                let (fine, mut fine_layers, fine_all) = layers(
                    "sampler sub-pixel depths (f32 bits)",
                    side,
                    wgpu::TextureFormat::R32Uint,
                    usage,
                );
                let (full, full_layers, full_all) = layers(
                    "sampler covered-pixel depths (f32 bits)",
                    r,
                    wgpu::TextureFormat::R32Uint,
                    usage,
                );
                fine_layers.extend(full_layers);
                // The five views' fill dispatches, then a round's set-up dispatch.
                let args = storage_buffer(
                    gpu,
                    6 * 16,
                    wgpu::BufferUsages::INDIRECT,
                    "sampler fill and set-up dispatches",
                )?;
                Maps::Compute {
                    _fine: fine,
                    _full: full,
                    layers: fine_layers,
                    fine_all,
                    full_all,
                    args,
                }
            }
        };
        let (front, sides) = hc.corner_norms();
        let norm_data: Vec<f32> = front.iter().chain(sides).copied().collect();
        let norms = storage_buffer(
            gpu,
            4 * norm_data.len() as u64,
            wgpu::BufferUsages::empty(),
            "sampler corner norms",
        )?;
        gpu.queue
            .write_buffer(&norms, 0, bytemuck::cast_slice(&norm_data));
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("sampler parameters"),
            size: PARAM_SLOT * SLOTS,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let stamps = gpu.timestamp_period.map(|_| Stamps {
            set: device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("sampler pass timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: 2 * STAMP_PAIRS as u32,
            }),
            resolved: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("sampler resolved timestamps"),
                size: STAMP_STRIDE * STAMP_PAIRS as u64,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            }),
        });
        let round_params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("sampler round parameters"),
            size: PARAM_SLOT * ROUNDS as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        // Created zeroed (wgpu clears new buffers): the first round's stay so.
        let firsts = std::array::from_fn(|_| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("sampler round's first draws"),
                size: 5 * 16,
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_DST
                    | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            })
        });
        scope.check()?;
        Ok(GpuSampler {
            gpu,
            scene,
            round_params,
            firsts,
            pix_off,
            culling: true,
            hc,
            maps,
            params,
            norms,
            draws,
            pedges,
            pplanes,
            indirect,
            frame: None,
            frame_u: None,
            parts_u: None,
            parts_f: None,
            flags: None,
            staging: None,
            tris: None,
            tflags: None,
            last_draws: 0,
            last_first_round: 0,
            rendered: false,
            stamps,
            times: SamplerTimes::default(),
        })
    }

    /// Device bytes a [`GpuSampler`] of `res` pixels across takes for `scene` (made with
    /// [`GpuSampler::new`]): its sub-pixel maps (five layers of `8R × 8R`, `R` the resolution
    /// rounded up to a multiple of 16), its per-pixel layers, and the set-up's output (the
    /// draws, each polygon point's edge, each polygon's plane, the rounds' cluster states and
    /// lists); the per-render buffers of the boxes and triangles tested come on top.
    pub fn device_bytes(scene: &GpuSamplerScene, res: u32) -> u64 {
        let r = u64::from(res.max(16).div_ceil(16) * 16);
        let side = u64::from(SUB) * r;
        let per_pixel = match scene.fill {
            // The pixels' depths, and the compute fill's covered pixels.
            FillPipelines::Render { .. } => 4,
            FillPipelines::Compute { .. } => 8,
        };
        5 * 4 * side * side
            + 5 * per_pixel * r * r
            + 5 * DRAW_BYTES * u64::from(scene.cap)
            + (16 * scene.points_len).next_multiple_of(PIX_ALIGN)
            + 48 * u64::from(scene.polys)
            + 4 * u64::from(Layout::new(scene.clusters.len()).end)
    }

    /// The CPU hemicube that sets up each render (for its settings:
    /// [`Hemicube::set_subpixel`], [`Hemicube::set_depth_bounded`]).
    pub fn hemicube(&mut self) -> &mut Hemicube {
        &mut self.hc
    }

    /// [`Hemicube::begin`]: the next test renders from `eye`.
    pub fn begin(&mut self, eye: DVec3, axis: usize, sign: f64, eps: f64, boxes: &[DAabb]) {
        self.rendered = false;
        self.hc.begin(eye, axis, sign, eps, boxes);
    }

    /// [`Hemicube::begin_patch`]: the next test renders for the rectangle.
    pub fn begin_patch(
        &mut self,
        eye: DVec3,
        axis: usize,
        sign: f64,
        half: [f64; 2],
        boxes: &[DAabb],
    ) {
        self.rendered = false;
        self.hc.begin_patch(eye, axis, sign, half, boxes);
    }

    /// Turns rendering in rounds on (the default) or off. With it, where the fill is
    /// [`SamplerFill::Compute`], a render first draws the polygons of the nearest clusters (of
    /// 32 polygons in Morton order; the nearest 1/64 of them, then shells out to 1/32, 1/16,
    /// 1/8, 1/4, 40 %, 60 % and all by distance), then, round by round, takes the largest
    /// sub-pixel depth of each pixel and draws only the clusters of the next shell whose box
    /// can still lower a pixel some test reads (`cull` in `shaders/sampler_setup.wgsl`): far
    /// leaves behind near ones are not set up at all, as the CPU's traversal skips them. It
    /// changes no test's answer, only the work ([`GpuSampler::last_draws`]). Off, or with the
    /// render fill, every polygon is set up in one round.
    pub fn set_culling(&mut self, on: bool) {
        self.culling = on;
    }

    /// GPU time of this sampler's passes by phase since it was made ([`SamplerTimes`]).
    pub fn gpu_times(&self) -> SamplerTimes {
        self.times
    }

    /// The draws (one polygon in one view) of the last [`GpuSampler::test_boxes`].
    pub fn last_draws(&self) -> u64 {
        self.last_draws
    }

    /// Of [`GpuSampler::last_draws`], those of the first round ([`GpuSampler::set_culling`];
    /// all of them in one round).
    pub fn last_first_round_draws(&self) -> u64 {
        self.last_first_round
    }

    /// Tests `boxes` (each given to the last `begin`, or inside their pixels) as
    /// [`Hemicube::test_box`] does: true for a box hidden from every point of the ball (or
    /// rectangle), looking out through the face. The first test after a `begin` also renders
    /// (in the same submission); later ones reuse the maps.
    ///
    /// # Errors
    /// The device's failures ([`BackendError::device_failed`]), and
    /// [`BackendError::BufferTooLarge`] for more boxes than a buffer holds or more draws than
    /// a view's share of the draws' buffer.
    pub fn test_boxes(&mut self, boxes: &[DAabb]) -> Result<Vec<bool>, BackendError> {
        Ok(self.submit(boxes, &[], None)?.0)
    }

    /// Tests triangles (each inside the boxes given to the last `begin`) as
    /// [`Hemicube::test_triangle`] does, pixel by pixel with the triangle's own part in each
    /// pixel: true for a hidden one. A triangle reaching the eye is decided by its box, as on
    /// the CPU.
    ///
    /// # Errors
    /// As [`GpuSampler::test_boxes`].
    pub fn test_triangles(&mut self, tris: &[[DVec3; 3]]) -> Result<Vec<bool>, BackendError> {
        let (_, codes) = self.submit(&[], tris, None)?;
        self.triangles_hidden(tris, &codes)
    }

    /// [`GpuSampler::test_triangles`] for triangles of the scene whose triangles were
    /// uploaded ([`GpuSamplerScene::upload_triangles`]): `ids[k]` is the index there of
    /// `tris[k]`, and only the indices go up. Without resident triangles, as
    /// [`GpuSampler::test_triangles`]. The same answers either way.
    ///
    /// # Errors
    /// As [`GpuSampler::test_boxes`].
    ///
    /// # Panics
    /// When `ids` and `tris` differ in length, or an index is not below
    /// [`GpuSamplerScene::resident_triangles`] (with resident triangles).
    pub fn test_scene_triangles(
        &mut self,
        ids: &[u32],
        tris: &[[DVec3; 3]],
    ) -> Result<Vec<bool>, BackendError> {
        Ok(self.test_boxes_and_scene_triangles(&[], ids, tris)?.1)
    }

    /// [`GpuSampler::test_boxes`] and [`GpuSampler::test_scene_triangles`] in one submission
    /// (a second only for triangles reaching the eye, whose boxes decide): the boxes' and the
    /// triangles' hidden flags, each as the two would answer apart. (Testing an object's
    /// pieces and all their triangles this way saves a submission per band but tests the
    /// triangles of pieces whose boxes are hidden too: on lavapipe a coarse forest's cell
    /// took twice as long, so the bake does not, until a real GPU has measured it;
    /// `docs/sampling.md`.)
    fn test_boxes_and_scene_triangles(
        &mut self,
        boxes: &[DAabb],
        ids: &[u32],
        tris: &[[DVec3; 3]],
    ) -> Result<(Vec<bool>, Vec<bool>), BackendError> {
        assert_eq!(ids.len(), tris.len(), "one index per triangle");
        let resident = self.scene.triangle_count;
        let ids = (resident > 0).then_some(ids);
        if let Some(ids) = ids {
            assert!(
                ids.iter().all(|&t| t < resident),
                "triangle indices below {resident}"
            );
        }
        let (hidden, codes) = self.submit(boxes, tris, ids)?;
        Ok((hidden, self.triangles_hidden(tris, &codes)?))
    }

    /// The triangles' hidden flags from their codes: those reaching the eye are decided by
    /// their boxes.
    fn triangles_hidden(
        &mut self,
        tris: &[[DVec3; 3]],
        codes: &[u32],
    ) -> Result<Vec<bool>, BackendError> {
        let mut hidden: Vec<bool> = codes.iter().map(|&c| c == 0).collect();
        // Those reaching the eye: their boxes decide.
        let reach: Vec<usize> = (0..tris.len()).filter(|&t| codes[t] == 2).collect();
        if !reach.is_empty() {
            let boxes: Vec<DAabb> = reach
                .iter()
                .map(|&t| {
                    let [a, b, c] = tris[t];
                    DAabb {
                        min: a.min(b).min(c),
                        max: a.max(b).max(c),
                    }
                })
                .collect();
            for (&t, h) in reach.iter().zip(self.test_boxes(&boxes)?) {
                hidden[t] = h;
            }
        }
        Ok(hidden)
    }

    /// One submission: the render (unless done since the last `begin`), the boxes' parts and
    /// the triangles tested (with `ids`, their indices among the scene's resident triangles go
    /// up instead of their corners). Returns the boxes' hidden flags and the triangles' codes
    /// (0 hidden, 1 open, 2 reaching the eye).
    fn submit(
        &mut self,
        boxes: &[DAabb],
        tris: &[[DVec3; 3]],
        ids: Option<&[u32]>,
    ) -> Result<(Vec<bool>, Vec<u32>), BackendError> {
        let gpu = self.gpu;
        gpu.check_failure()?;
        let res = self.hc.resolution() as u32;
        // The boxes' parts; a box open without a pixel test is open from the start.
        let mut open = vec![0u32; boxes.len().max(1)];
        let mut rects: Vec<BoxRect> = Vec::new();
        let mut parts_u: Vec<[u32; 4]> = Vec::new();
        let mut parts_f: Vec<f64> = Vec::new();
        for (b, bx) in boxes.iter().enumerate() {
            rects.clear();
            if !self.hc.box_rects(bx, &mut rects) {
                open[b] = 1;
                continue;
            }
            for r in &rects {
                parts_u.push([
                    b as u32,
                    u32::from(r.view),
                    r.i[0] | r.i[1] << 16,
                    r.j[0] | r.j[1] << 16,
                ]);
                parts_f
                    .extend_from_slice(&[r.pu[0], r.pu[1], r.pv[0], r.pv[1], r.z, 0.0, 0.0, 0.0]);
            }
        }
        let n_parts = parts_u.len() as u32;
        // Never an empty buffer.
        parts_u.push([0; 4]);
        parts_f.push(0.0);
        let cap = self.scene.cap;
        let (frame, frame_u) = self.hc.setup_frame(self.scene.polys, cap);
        // The triangles after the eye (their corners, or their indices among the resident
        // ones: exact in `f64`); one reaching beyond the farthest box is open at once.
        let mut tri_f: Vec<f64> = vec![frame[0], frame[1], frame[2], 0.0];
        let mut tri_codes = vec![0u32; tris.len().max(1)];
        for (t, tri) in tris.iter().enumerate() {
            if self.hc.beyond_bound(tri) {
                tri_codes[t] = 1;
            }
            match ids {
                Some(ids) => tri_f.push(f64::from(ids[t])),
                None => tri_f.extend(tri.iter().flat_map(|p| p.to_array())),
            }
        }
        let n_tris = tris.len() as u32;
        let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let scope = ErrorScopes::push(&gpu.device);
        let mut uploaded = 0u64;
        // The frame goes up with the render and stays for later tests of it.
        let frame_slots = [
            (
                &mut self.frame,
                bytemuck::cast_slice::<_, u8>(&frame),
                "sampler frame",
            ),
            (
                &mut self.frame_u,
                bytemuck::cast_slice(&frame_u),
                "sampler frame words",
            ),
        ];
        let frame_slots = frame_slots.into_iter().filter(|_| !self.rendered);
        for (slot, bytes, label) in frame_slots.chain([
            (
                &mut self.parts_u,
                bytemuck::cast_slice(&parts_u),
                "sampler box parts",
            ),
            (
                &mut self.parts_f,
                bytemuck::cast_slice(&parts_f),
                "sampler box part bounds",
            ),
            (
                &mut self.tris,
                bytemuck::cast_slice(&tri_f),
                "sampler triangles",
            ),
        ]) {
            gpu.ensure_buffer(slot, bytes.len() as u64, storage, label)?;
            if let Some(b) = slot {
                gpu.queue.write_buffer(b, 0, bytes);
            }
            uploaded += bytes.len() as u64;
        }
        let flag_bytes = 4 * open.len() as u64;
        gpu.ensure_buffer(
            &mut self.flags,
            flag_bytes,
            storage | wgpu::BufferUsages::COPY_SRC,
            "sampler flags",
        )?;
        let tflag_bytes = 4 * tri_codes.len() as u64;
        gpu.ensure_buffer(
            &mut self.tflags,
            tflag_bytes,
            storage | wgpu::BufferUsages::COPY_SRC,
            "sampler triangle flags",
        )?;
        // The flags, the triangles' codes, then the five indirect draws (instance counts).
        let read_bytes = flag_bytes + tflag_bytes + 2 * 5 * 16;
        // Then the timestamp pairs.
        let stamp_bytes = if self.stamps.is_some() {
            16 * STAMP_PAIRS as u64
        } else {
            0
        };
        gpu.ensure_buffer(
            &mut self.staging,
            read_bytes + stamp_bytes,
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            "sampler read-back",
        )?;
        let (
            Some(frame_b),
            Some(frame_u_b),
            Some(parts_u_b),
            Some(parts_f_b),
            Some(flags_b),
            Some(staging),
            Some(tris_b),
            Some(tflags_b),
        ) = (
            &self.frame,
            &self.frame_u,
            &self.parts_u,
            &self.parts_f,
            &self.flags,
            &self.staging,
            &self.tris,
            &self.tflags,
        )
        else {
            unreachable!("every buffer was just ensured");
        };
        gpu.queue
            .write_buffer(flags_b, 0, bytemuck::cast_slice(&open));
        gpu.queue
            .write_buffer(tflags_b, 0, bytemuck::cast_slice(&tri_codes));
        let render = !self.rendered;
        let layout = Layout::new(self.scene.clusters.len());
        let mut first_list: Vec<u32> = Vec::new();
        // Rounds only with the compute fill (the render fill draws each view's list once).
        let in_rounds = render
            && self.culling
            && matches!(self.maps, Maps::Compute { .. })
            && self.scene.clusters.len() > ROUNDS_MIN;
        if render {
            let indirect_init: Vec<u32> = (0..5).flat_map(|_| [6u32, 0, 0, 0]).collect();
            gpu.queue
                .write_buffer(&self.indirect, 0, bytemuck::cast_slice(&indirect_init));
            let (states, limits) = round_states(&self.scene.clusters, self.hc.eye(), in_rounds);
            gpu.queue
                .write_buffer(&self.indirect, 80, bytemuck::cast_slice(&states));
            // The first round's list (the clusters it draws) and every round's length.
            if in_rounds {
                first_list = (0..states.len() as u32)
                    .filter(|&c| states[c as usize] == 1)
                    .collect();
            }
            let mut lens = [0u32; ROUNDS];
            lens[0] = first_list.len() as u32;
            let word = |w: u32| 4 * u64::from(w);
            gpu.queue.write_buffer(
                &self.indirect,
                word(layout.counts),
                bytemuck::cast_slice(&lens),
            );
            if !first_list.is_empty() {
                gpu.queue.write_buffer(
                    &self.indirect,
                    word(layout.list(0)),
                    bytemuck::cast_slice(&first_list),
                );
            }
            for (r, limit) in limits.into_iter().enumerate() {
                let p = RoundParams {
                    round: r as u32 + 1,
                    limit: limit.to_bits(),
                    pix: (self.pix_off / 16) as u32,
                    boxes: 3 * self.scene.points_len as u32,
                    clusters: self.scene.clusters.len() as u32,
                    list: if in_rounds { layout.list(r) } else { u32::MAX },
                    count: layout.counts + r as u32,
                    pad: 0,
                };
                gpu.queue.write_buffer(
                    &self.round_params,
                    r as u64 * PARAM_SLOT,
                    bytemuck::bytes_of(&p),
                );
                // The round's set-up dispatch reads its list's length.
                let sp = Params {
                    n: layout.counts + r as u32,
                    ..Params::default()
                };
                gpu.queue.write_buffer(
                    &self.params,
                    (8 + r as u64) * PARAM_SLOT,
                    bytemuck::bytes_of(&sp),
                );
            }
            uploaded += 4 * (states.len() + ROUNDS + first_list.len()) as u64
                + (ROUND_BYTES + std::mem::size_of::<Params>() as u64) * ROUNDS as u64;
        }
        let subpixel = u32::from(self.hc.subpixel());
        let (axis, sign) = (frame_u[0], frame_u[1]);
        for k in 0..5u32 {
            let p = Params {
                res,
                view: k,
                subpixel,
                rows: if k == 0 { res } else { res / 2 },
                axis,
                sign,
                base: k * cap,
                // The compute fill's bound on a view's draws.
                n: cap,
                ..Params::default()
            };
            gpu.queue.write_buffer(
                &self.params,
                u64::from(k) * PARAM_SLOT,
                bytemuck::bytes_of(&p),
            );
        }
        let pixels = 5 * res * res;
        let reduce_groups = dispatch(pixels.div_ceil(WORKGROUP));
        let test_groups = dispatch(n_parts);
        // Every polygon, or with rounds the first round's clusters (two per workgroup).
        let setup_groups = if in_rounds {
            dispatch((first_list.len() as u32).div_ceil(WORKGROUP / CLUSTER))
        } else {
            dispatch(self.scene.polys.div_ceil(WORKGROUP))
        };
        let reduce_p = Params {
            res,
            n: pixels,
            groups_x: reduce_groups.0,
            ..Params::default()
        };
        let test_p = Params {
            res,
            n: n_parts,
            groups_x: test_groups.0,
            ..Params::default()
        };
        gpu.queue
            .write_buffer(&self.params, 5 * PARAM_SLOT, bytemuck::bytes_of(&reduce_p));
        gpu.queue
            .write_buffer(&self.params, 6 * PARAM_SLOT, bytemuck::bytes_of(&test_p));
        let tri_groups = dispatch((5 * n_tris).div_ceil(WORKGROUP));
        let tri_p = Params {
            res,
            n: n_tris,
            groups_x: tri_groups.0,
            axis,
            sign,
            tri_ids: u32::from(ids.is_some()),
            ..Params::default()
        };
        gpu.queue
            .write_buffer(&self.params, 7 * PARAM_SLOT, bytemuck::bytes_of(&tri_p));
        uploaded += SLOTS * std::mem::size_of::<Params>() as u64 + flag_bytes + tflag_bytes + 80;
        let param_entry = wgpu::BindGroupEntry {
            binding: 0,
            resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer: &self.params,
                offset: 0,
                size: NonZeroU64::new(std::mem::size_of::<Params>() as u64),
            }),
        };
        let setup_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("sampler set-up bind group"),
            layout: &self.scene.setup_layout,
            entries: &[
                entry(0, frame_b),
                entry(1, frame_u_b),
                entry(2, &self.scene.poly_buf),
                entry(3, &self.scene.points),
                entry(4, &self.draws),
                entry(5, &self.pedges),
                entry(6, &self.pplanes),
                entry(7, &self.indirect),
                wgpu::BindGroupEntry {
                    binding: 9,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: &self.round_params,
                        offset: 0,
                        size: NonZeroU64::new(ROUND_BYTES),
                    }),
                },
            ],
        });
        // The round's slot of the round parameters.
        let round_slot = |round: usize| [(round as u64 * PARAM_SLOT) as u32];
        let fill_entries = [
            param_entry.clone(),
            entry(1, &self.draws),
            entry(2, &self.pedges),
            entry(3, &self.pplanes),
            entry(4, &self.norms),
        ];
        let view_entry = |binding, view| wgpu::BindGroupEntry {
            binding,
            resource: wgpu::BindingResource::TextureView(view),
        };
        let mut test_entries = vec![
            param_entry,
            wgpu::BindGroupEntry {
                binding: 6,
                resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer: &self.pedges,
                    offset: self.pix_off,
                    size: NonZeroU64::new(4 * 5 * u64::from(res) * u64::from(res)),
                }),
            },
            entry(7, parts_u_b),
            entry(8, parts_f_b),
            entry(9, flags_b),
            entry(10, tris_b),
            entry(11, tflags_b),
            entry(12, frame_u_b),
            entry(19, &self.scene.triangles),
        ];
        // Per round (the render fill has one).
        let mut args_groups = Vec::new();
        let fill_groups: Vec<wgpu::BindGroup> = match (&self.scene.fill, &self.maps) {
            (FillPipelines::Render { layout, .. }, Maps::Render { all, .. }) => {
                test_entries.push(view_entry(5, all));
                vec![gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("sampler fill bind group"),
                    layout,
                    entries: &fill_entries,
                })]
            }
            (
                FillPipelines::Compute {
                    layout,
                    args_layout,
                    ..
                },
                Maps::Compute {
                    fine_all,
                    full_all,
                    args,
                    ..
                },
            ) => {
                test_entries.extend([view_entry(5, fine_all), view_entry(13, full_all)]);
                self.firsts
                    .iter()
                    .map(|firsts| {
                        args_groups.push(gpu.device.create_bind_group(
                            &wgpu::BindGroupDescriptor {
                                label: Some("sampler fill arguments bind group"),
                                layout: args_layout,
                                entries: &[
                                    fill_entries[0].clone(),
                                    entry(14, &self.indirect),
                                    entry(17, args),
                                    entry(18, firsts),
                                ],
                            },
                        ));
                        let mut entries = fill_entries.to_vec();
                        entries.extend([
                            entry(14, &self.indirect),
                            view_entry(15, fine_all),
                            view_entry(16, full_all),
                            entry(18, firsts),
                        ]);
                        gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                            label: Some("sampler compute fill bind group"),
                            layout,
                            entries: &entries,
                        })
                    })
                    .collect()
            }
            _ => unreachable!("a sampler's maps are made for its scene's fill"),
        };
        let test_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("sampler test bind group"),
            layout: &self.scene.test_layout,
            entries: &test_entries,
        });
        let mut encoder = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("sampler encoder"),
            });
        // The phase (0 set-up, 1 fill, 2 reduce, 3 tests) of each timed pass, in the order of
        // their timestamp pairs.
        let mut phases: Vec<usize> = Vec::new();
        let stamps = self.stamps.as_ref();
        let mut pair = |phase: usize| -> Option<(&wgpu::QuerySet, u32)> {
            let s = stamps?;
            phases.push(phase);
            Some((&s.set, 2 * (phases.len() as u32 - 1)))
        };
        if render && self.scene.polys > 0 {
            let mut cp = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("sampler set-up pass"),
                timestamp_writes: compute_writes(pair(0)),
            });
            cp.set_pipeline(&self.scene.setup);
            cp.set_bind_group(0, &setup_group, &round_slot(0));
            cp.dispatch_workgroups(setup_groups.0, setup_groups.1, 1);
        }
        // A layer cleared (to `clear`) by a render pass, which draws into it when `draw`
        // gives the pipeline, bind group, view and rows.
        type Draw<'p> = (&'p wgpu::RenderPipeline, &'p wgpu::BindGroup, usize, u32);
        let clear_pass = |encoder: &mut wgpu::CommandEncoder,
                          view,
                          clear: f64,
                          draw: Option<Draw<'_>>,
                          stamp: Option<(&wgpu::QuerySet, u32)>| {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("sampler fill pass"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color {
                            r: clear,
                            g: 0.0,
                            b: 0.0,
                            a: 0.0,
                        }),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: stamp.map(|(query_set, i)| wgpu::RenderPassTimestampWrites {
                    query_set,
                    beginning_of_pass_write_index: Some(i),
                    end_of_pass_write_index: Some(i + 1),
                }),
                occlusion_query_set: None,
                multiview_mask: None,
            });
            if let Some((pipeline, group, k, rows)) = draw {
                pass.set_viewport(0.0, 0.0, (SUB * res) as f32, (SUB * rows) as f32, 0.0, 1.0);
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, group, &[(k as u64 * PARAM_SLOT) as u32]);
                pass.draw_indirect(&self.indirect, 16 * k as u64);
            }
        };
        // One round of the compute fill: its dispatches from the round's draw counts, then
        // the draws.
        let compute_round =
            |encoder: &mut wgpu::CommandEncoder,
             round: usize,
             stamps: [Option<(&wgpu::QuerySet, u32)>; 2]| {
                let (FillPipelines::Compute { args, fill, .. }, Maps::Compute { args: a, .. }) =
                    (&self.scene.fill, &self.maps)
                else {
                    unreachable!("rounds of the compute fill only");
                };
                {
                    let mut cp = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                        label: Some("sampler fill arguments pass"),
                        timestamp_writes: compute_writes(stamps[0]),
                    });
                    cp.set_pipeline(args);
                    cp.set_bind_group(0, &args_groups[round], &[0]);
                    cp.dispatch_workgroups(1, 1, 1);
                }
                let mut cp = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("sampler compute fill pass"),
                    timestamp_writes: compute_writes(stamps[1]),
                });
                cp.set_pipeline(fill);
                for k in 0..5u64 {
                    cp.set_bind_group(0, &fill_groups[round], &[(k * PARAM_SLOT) as u32]);
                    cp.dispatch_workgroups_indirect(a, 16 * k);
                }
            };
        let reduce_pass = |encoder: &mut wgpu::CommandEncoder, stamp| {
            let mut cp = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("sampler reduce pass"),
                timestamp_writes: compute_writes(stamp),
            });
            cp.set_pipeline(&self.scene.reduce);
            cp.set_bind_group(0, &test_group, &[(5 * PARAM_SLOT) as u32]);
            cp.dispatch_workgroups(reduce_groups.0, reduce_groups.1, 1);
        };
        match (&self.scene.fill, &self.maps) {
            _ if !render => {}
            (FillPipelines::Render { pipeline, .. }, Maps::Render { layers, .. }) => {
                for (k, view) in layers.iter().enumerate() {
                    let rows = if k == 0 { res } else { res / 2 };
                    let draw = (pipeline, &fill_groups[0], k, rows);
                    clear_pass(&mut encoder, view, f64::INFINITY, Some(draw), pair(1));
                }
            }
            (FillPipelines::Compute { .. }, Maps::Compute { layers, .. }) => {
                // Infinity's bits: the clear value of a `R32Uint` target is converted to an
                // integer.
                for view in layers {
                    clear_pass(
                        &mut encoder,
                        view,
                        f64::from(f32::INFINITY.to_bits()),
                        None,
                        None,
                    );
                }
                let stamps = [pair(1), pair(1)];
                compute_round(&mut encoder, 0, stamps);
            }
            _ => unreachable!("a sampler's maps are made for its scene's fill"),
        }
        if render {
            reduce_pass(&mut encoder, pair(2));
        }
        let rounds = if in_rounds { ROUNDS } else { 1 };
        for (round, firsts) in self.firsts.iter().enumerate().take(rounds).skip(1) {
            // A later round: the draws from here on, the clusters of its shell that the depths
            // so far do not hide, their set-up, fill and the pixels' depths again.
            encoder.copy_buffer_to_buffer(&self.indirect, 0, firsts, 0, 80);
            {
                let groups = dispatch((self.scene.clusters.len() as u32).div_ceil(WORKGROUP));
                let mut cp = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("sampler cluster cull pass"),
                    timestamp_writes: compute_writes(pair(4)),
                });
                cp.set_pipeline(&self.scene.cull);
                cp.set_bind_group(0, &setup_group, &round_slot(round));
                cp.dispatch_workgroups(groups.0, groups.1, 1);
            }
            let (FillPipelines::Compute { setup_args, .. }, Maps::Compute { args: a, .. }) =
                (&self.scene.fill, &self.maps)
            else {
                unreachable!("rounds of the compute fill only");
            };
            {
                let mut cp = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("sampler set-up dispatch pass"),
                    timestamp_writes: None,
                });
                cp.set_pipeline(setup_args);
                cp.set_bind_group(
                    0,
                    &args_groups[round],
                    &[((8 + round as u64) * PARAM_SLOT) as u32],
                );
                cp.dispatch_workgroups(1, 1, 1);
            }
            {
                let mut cp = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("sampler set-up pass"),
                    timestamp_writes: compute_writes(pair(0)),
                });
                cp.set_pipeline(&self.scene.setup);
                cp.set_bind_group(0, &setup_group, &round_slot(round));
                cp.dispatch_workgroups_indirect(a, 80);
            }
            let stamps = [pair(1), pair(1)];
            compute_round(&mut encoder, round, stamps);
            reduce_pass(&mut encoder, pair(2));
        }
        if n_parts > 0 {
            let mut cp = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("sampler test pass"),
                timestamp_writes: compute_writes(pair(3)),
            });
            cp.set_pipeline(&self.scene.test);
            cp.set_bind_group(0, &test_group, &[(6 * PARAM_SLOT) as u32]);
            cp.dispatch_workgroups(test_groups.0, test_groups.1, 1);
        }
        if n_tris > 0 {
            let mut cp = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("sampler triangle test pass"),
                timestamp_writes: compute_writes(pair(3)),
            });
            cp.set_pipeline(&self.scene.test_tri);
            cp.set_bind_group(0, &test_group, &[(7 * PARAM_SLOT) as u32]);
            cp.dispatch_workgroups(tri_groups.0, tri_groups.1, 1);
        }
        encoder.copy_buffer_to_buffer(flags_b, 0, staging, 0, flag_bytes);
        encoder.copy_buffer_to_buffer(tflags_b, 0, staging, flag_bytes, tflag_bytes);
        encoder.copy_buffer_to_buffer(&self.indirect, 0, staging, flag_bytes + tflag_bytes, 80);
        // The second round's starts (the first round's draw counts): the first round's draws.
        encoder.copy_buffer_to_buffer(
            &self.firsts[1],
            0,
            staging,
            flag_bytes + tflag_bytes + 80,
            80,
        );
        if let Some(st) = stamps {
            for p in 0..phases.len() as u64 {
                let first = 2 * p as u32;
                encoder.resolve_query_set(
                    &st.set,
                    first..first + 2,
                    &st.resolved,
                    STAMP_STRIDE * p,
                );
                encoder.copy_buffer_to_buffer(
                    &st.resolved,
                    STAMP_STRIDE * p,
                    staging,
                    read_bytes + 16 * p,
                    16,
                );
            }
        }
        let read_bytes = read_bytes + 16 * phases.len() as u64;
        let submission = gpu.submit_commands(encoder.finish());
        scope.check()?;
        let (tx, rx) = std::sync::mpsc::channel();
        staging
            .slice(..read_bytes)
            .map_async(wgpu::MapMode::Read, move |r| {
                let _ = tx.send(r);
            });
        gpu.poll_until(&submission, "a sampler render", || match rx.try_recv() {
            Ok(r) => r.map(|()| true).map_err(|e| BackendError::ReadBack {
                step: "sampler flags",
                message: e.to_string(),
            }),
            Err(_) => Ok(false),
        })?;
        let (hidden, codes, draws) = {
            let view = staging
                .slice(..read_bytes)
                .get_mapped_range()
                .map_err(|e| BackendError::ReadBack {
                    step: "sampler flags mapping",
                    message: e.to_string(),
                })?;
            let words: Vec<u32> = view
                .chunks_exact(4)
                .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect();
            let hidden: Vec<bool> = words[..boxes.len()].iter().map(|&w| w == 0).collect();
            let codes: Vec<u32> = words[open.len()..open.len() + tris.len()].to_vec();
            let base = open.len() + tri_codes.len();
            // The timestamp pairs after the draw counts.
            let ticks = &words[base + 40..];
            let period = gpu.timestamp_period.unwrap_or(0.0);
            for (k, &phase) in phases.iter().enumerate() {
                let at = |w: usize| u64::from(ticks[w]) | u64::from(ticks[w + 1]) << 32;
                let dt = at(4 * k + 2).saturating_sub(at(4 * k));
                let d = std::time::Duration::from_nanos((dt as f64 * period).round() as u64);
                let t = &mut self.times;
                *[
                    &mut t.setup,
                    &mut t.fill,
                    &mut t.reduce,
                    &mut t.tests,
                    &mut t.cull,
                ][phase] += d;
                t.passes += 1;
            }
            let draws: Vec<u64> = (0..5).map(|k| u64::from(words[base + 4 * k + 1])).collect();
            let first: u64 = (0..5)
                .map(|k| u64::from(words[base + 20 + 4 * k + 1]))
                .sum();
            self.last_first_round = if in_rounds { first } else { draws.iter().sum() };
            (hidden, codes, draws)
        };
        staging.unmap();
        if !render {
            gpu.add_totals(&super::RenderStats {
                submissions: 1,
                passes: usize::from(n_parts > 0) + usize::from(n_tris > 0),
                bytes_uploaded: uploaded,
                bytes_read_back: read_bytes,
                ..super::RenderStats::default()
            });
            return Ok((hidden, codes));
        }
        self.rendered = true;
        self.last_draws = draws.iter().sum();
        if let Some(&most) = draws.iter().max()
            && most > u64::from(cap)
        {
            return Err(BackendError::BufferTooLarge {
                label: "sampler draws",
                size: 5 * DRAW_BYTES * most,
                max: 5 * DRAW_BYTES * u64::from(cap),
            });
        }
        gpu.add_totals(&super::RenderStats {
            submissions: 1,
            // Set-up and reduce, and the render fill's five passes or the compute fill's ten
            // clears and two compute passes; each later round's cull, set-up, fill and reduce.
            passes: match self.maps {
                Maps::Render { .. } => 7,
                Maps::Compute { .. } => 14,
            } + 5 * (ROUNDS - 1) * usize::from(in_rounds)
                + usize::from(n_parts > 0)
                + usize::from(n_tris > 0),
            bytes_uploaded: uploaded,
            bytes_read_back: read_bytes,
            ..super::RenderStats::default()
        });
        Ok((hidden, codes))
    }
}
