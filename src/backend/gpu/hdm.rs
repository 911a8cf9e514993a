//! The Hierarchical Depth Map on the device: for the planes whose occludee tests the caller
//! asks the device to answer ([`RasterBackend::render_tested`]), their maps stay on the GPU.
//! One compute pass per submission copies each such plane's target into a storage buffer,
//! builds its max/min pyramid level by level and answers every query of the submission
//! (`shaders/hdm.wgsl`); only the answers come back, four bytes a query, instead of the maps.
//!
//! # Why the answers are the CPU's
//! The shader is [`crate::hdm::Hdm::build`] and [`crate::hdm::Hdm::test`] written again: the
//! same children per texel, the same finest level spanning at most 2 × 2 texels, the same
//! descent into border texels. Depths are only compared (`max`, `min`, `<`, `>=`), never
//! computed with, and the comparisons of `f32` values are exact on every device, so each answer
//! equals the CPU's on the same map. The descent's explicit stack holds at most `4 + 3` entries
//! per level (64 for up to 20 levels); were it ever full the answer would be `Partial`, which
//! culls nothing.
//!
//! # Box tests
//! Where the device has `SHADER_F64` ([`BoxPipelines`]), a plane's queries may also be boxes
//! ([`crate::plane::PlaneQueries`]): `box_plan` (`shaders/boxes.wgsl`) computes each box's
//! rectangle tests from the box and the plane's frame with the CPU's `f64` expressions
//! ([`crate::project::occludee::box_coverage`]) into [`BOX_SLOTS`] query slots after the
//! submission's rectangle tests, `answer` answers them with the rest, and `box_decide`
//! combines them as the rule does into one answer per box, the only word read back. IEEE `f64`
//! arithmetic gives the CPU's values; a driver that fuses a multiply and an add moves one by an
//! ulp, a ten-thousandth of the rectangles' outward padding (`1e-12` of their coordinates), so
//! a rectangle still holds the exact one (conservative) and differs from the CPU's only where
//! a pixel boundary falls within that ulp.
//!
//! # Kept sweep planes
//! A plane whose map the caller asks to keep ([`RasterBackend::render_kept`]: an occlusion
//! sweep's) is also a reprojection source for later planes. The same pass builds its
//! summed-area table of the pixels outside the umbra from its pyramid's level 0 (`sat_rows`,
//! `sat_cols`; the twin of `prepare::umbra_table`, integer counts, so the CPU's table exactly),
//! which is copied into a reprojection table texture and cached for the map's stand-in
//! ([`super::tables::TableCache`]); the umbra's bounding box and the count of pixels outside
//! it come back, 32 bytes a plane ([`KeptPlane`]).
//!
//! [`RasterBackend::render_tested`]: crate::backend::RasterBackend::render_tested
//! [`RasterBackend::render_kept`]: crate::backend::RasterBackend::render_kept

use super::UNIFORM_STRIDE;
use std::num::NonZeroU64;

/// Bytes of one query (`Query` in `shaders/hdm.wgsl`).
pub(super) const QUERY_BYTES: u64 = 16;
/// Bytes of one tested plane's entry (`Plane` in `shaders/hdm.wgsl`).
pub(super) const PLANE_BYTES: u64 = 16;
/// Invocations per workgroup of the answer pass.
const ANSWER_WORKGROUP: u32 = 64;
/// Invocations per workgroup side of the pyramid passes.
const LEVEL_WORKGROUP: u32 = 8;
/// Level slots per plane in the steps buffer (`MAX_LEVELS` in `shaders/hdm.wgsl`): maps up
/// to 2^15 pixels a side.
pub(super) const MAX_LEVELS: usize = 16;
/// Largest map side whose tests the device answers: the answer pass packs texel coordinates
/// in 14 bits (`level << 28 | tx << 14 | ty` in `shaders/hdm.wgsl`) and pixel coordinates in
/// 16. A larger map (possible on devices with 32,768-texel textures) comes back instead.
pub(super) const MAX_SIDE: u32 = 1 << 14;
/// Bytes of one level's parameters.
pub(super) const LEVEL_BYTES: u64 = std::mem::size_of::<LevelParams>() as u64;
/// Bytes of one kept plane's parameters (`Kept` in `shaders/hdm.wgsl`).
pub(super) const KEPT_BYTES: u64 = 32;
/// Words of one kept plane's summary (`SUMMARY` in `shaders/hdm.wgsl`).
pub(super) const SUMMARY_WORDS: u64 = 8;
/// Invocations per workgroup of the summed-area table passes.
const SAT_WORKGROUP: u32 = 64;

/// Where a kept plane ([`RasterBackend::render_kept`]) lies in a submission's buffers.
///
/// [`RasterBackend::render_kept`]: crate::backend::RasterBackend::render_kept
#[derive(Clone, Debug)]
pub(super) struct KeptPlane {
    /// Its index among the submission's kept planes (its summary's and parameters' slot).
    pub index: u32,
    /// Its table's first word in the tables buffer.
    pub table: u32,
    /// The table's row stride in words ([`table_stride`]).
    pub stride: u32,
}

/// The row stride in words of a kept plane's table `width` wide: a multiple of 64 words, as a
/// copy into a texture needs rows of a multiple of 256 bytes.
pub(super) fn table_stride(width: u32) -> u32 {
    width.next_multiple_of(64)
}

/// A kept plane's parameters (`Kept` in `shaders/hdm.wgsl`).
pub(super) fn kept_words(t: &TestedPlane, k: &KeptPlane) -> [u32; 8] {
    let l0 = &t.levels[0];
    [l0.dst, l0.dst_w, l0.dst_h, k.table, k.stride, 0, 0, 0]
}

/// A kept plane's summary before the passes: no umbra box yet, nothing counted.
pub(super) const SUMMARY_START: [u32; 8] = [u32::MAX, 0, u32::MAX, 0, 0, 0, 0, 0];

/// A kept plane's summary after the passes: the umbra's box `[i0, i1, j0, j1]` (`None`
/// without umbra) and the pixels outside it.
pub(super) fn read_summary(words: &[u32]) -> (Option<[u32; 4]>, u64) {
    let umbra = (words[0] != u32::MAX).then(|| [words[0], words[1], words[2], words[3]]);
    (umbra, u64::from(words[4]))
}

/// Workgroups of a summed-area table pass over `n` rows or columns.
pub(super) fn sat_groups(n: u32) -> u32 {
    n.div_ceil(SAT_WORKGROUP)
}

/// The sizes of the pyramid's levels over a `w × h` map, finest first, down to 1 × 1
/// (`Hdm::build`'s levels).
pub(super) fn level_sizes(w: u32, h: u32) -> Vec<(u32, u32)> {
    let mut sizes = vec![(w, h)];
    let (mut pw, mut ph) = (w, h);
    while pw > 1 || ph > 1 {
        (pw, ph) = ((pw / 2).max(1), (ph / 2).max(1));
        sizes.push((pw, ph));
    }
    sizes
}

/// `f32`s a plane's pyramid takes: its map, then a max and a min per coarser level.
pub(super) fn pyramid_floats(w: u32, h: u32) -> u64 {
    let sizes = level_sizes(w, h);
    let map = u64::from(w) * u64::from(h);
    map + sizes[1..]
        .iter()
        .map(|&(a, b)| 2 * u64::from(a) * u64::from(b))
        .sum::<u64>()
}

/// One level's parameters (`Level` in `shaders/hdm.wgsl`): a `base` dispatch's at its own
/// [`UNIFORM_STRIDE`] of the params buffer, a `reduce` level's in the steps buffer.
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub(super) struct LevelParams {
    src: u32,
    src_min: u32,
    dst: u32,
    dst_min: u32,
    src_w: u32,
    src_h: u32,
    pub dst_w: u32,
    pub dst_h: u32,
}

/// The params slot of the `reduce` dispatch of level `k` (every plane's): only `k`.
pub(super) fn reduce_slot(k: u32) -> LevelParams {
    LevelParams {
        src: k,
        ..LevelParams::default()
    }
}

/// The dispatches of one plane's pyramid whose map is `w × h` at `base` in the pyramid
/// buffer: the copy of the map (with its slice mask from word `mask` of the masks buffer, if
/// any), then one reduction per coarser level.
pub(super) fn level_params(w: u32, h: u32, base: u32, mask: Option<u32>) -> Vec<LevelParams> {
    let sizes = level_sizes(w, h);
    let mut out = vec![LevelParams {
        src: mask.unwrap_or(0),
        src_w: u32::from(mask.is_some()),
        dst: base,
        dst_min: base,
        dst_w: w,
        dst_h: h,
        ..LevelParams::default()
    }];
    let (mut src, mut src_min) = (base, base);
    let mut next = base + w * h;
    for k in 1..sizes.len() {
        let ((sw, sh), (dw, dh)) = (sizes[k - 1], sizes[k]);
        let p = LevelParams {
            src,
            src_min,
            dst: next,
            dst_min: next + dw * dh,
            src_w: sw,
            src_h: sh,
            dst_w: dw,
            dst_h: dh,
        };
        (src, src_min) = (p.dst, p.dst_min);
        next += 2 * dw * dh;
        out.push(p);
    }
    out
}

/// A compute pass's storage buffer binding of at least `size` bytes.
fn storage_entry(binding: u32, read_only: bool, size: u64) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: NonZeroU64::new(size),
        },
        count: None,
    }
}

/// The three compute pipelines of `shaders/hdm.wgsl` and their bind group layouts.
#[derive(Debug)]
pub(super) struct HdmPipelines {
    /// Copies a target into the pyramid buffer.
    pub base: wgpu::ComputePipeline,
    /// One level of the pyramid from the one below.
    pub reduce: wgpu::ComputePipeline,
    /// The queries.
    pub answer: wgpu::ComputePipeline,
    /// Group 0 of `base` and `reduce`: the level's parameters (dynamic offset), the pyramid.
    pub level_layout: wgpu::BindGroupLayout,
    /// Group 1 of `base`: the plane's target.
    pub map_layout: wgpu::BindGroupLayout,
    /// Group 0 of `answer`: the pyramid, the planes, the queries, the answers, the count.
    pub answer_layout: wgpu::BindGroupLayout,
    /// A kept plane's table along its rows (with its summary), then down its columns.
    pub sat_rows: wgpu::ComputePipeline,
    pub sat_cols: wgpu::ComputePipeline,
    /// Group 0 of `sat_rows` and `sat_cols`: the pyramid, the kept planes, the tables, the
    /// summaries.
    pub sat_layout: wgpu::BindGroupLayout,
}

impl HdmPipelines {
    /// Compiles `shaders/hdm.wgsl` and creates its pipelines on `device`, every object
    /// labelled.
    pub fn new(device: &wgpu::Device) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("hdm.wgsl"),
            source: wgpu::ShaderSource::Wgsl(super::HDM_WGSL.into()),
        });
        let cs = wgpu::ShaderStages::COMPUTE;
        let storage = storage_entry;
        let uniform = |binding: u32, dynamic: bool, size: u64| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: cs,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: dynamic,
                min_binding_size: NonZeroU64::new(size),
            },
            count: None,
        };
        let level_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("hdm level bind group layout"),
            entries: &[
                uniform(0, true, LEVEL_BYTES),
                storage(1, false, 4),
                storage(7, true, 4),
                storage(8, true, LEVEL_BYTES),
            ],
        });
        let map_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("hdm map bind group layout"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: cs,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: false },
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                count: None,
            }],
        });
        let answer_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("hdm answer bind group layout"),
            entries: &[
                storage(2, true, 4),
                storage(3, true, PLANE_BYTES),
                storage(4, true, QUERY_BYTES),
                storage(5, false, 4),
                uniform(6, false, 16),
            ],
        });
        let sat_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("hdm summed-area table bind group layout"),
            entries: &[
                storage(10, true, 4),
                storage(11, true, KEPT_BYTES),
                storage(12, false, 4),
                storage(13, false, SUMMARY_WORDS * 4),
            ],
        });
        let pipeline = |name: &str, entry: &str, layouts: &[Option<&wgpu::BindGroupLayout>]| {
            let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(&format!("hdm {name} pipeline layout")),
                bind_group_layouts: layouts,
                immediate_size: 0,
            });
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(&format!("hdm {name} pipeline")),
                layout: Some(&layout),
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        HdmPipelines {
            base: pipeline("base", "base", &[Some(&level_layout), Some(&map_layout)]),
            reduce: pipeline("reduce", "reduce", &[Some(&level_layout)]),
            answer: pipeline("answer", "answer", &[Some(&answer_layout)]),
            sat_rows: pipeline("table rows", "sat_rows", &[Some(&sat_layout)]),
            sat_cols: pipeline("table columns", "sat_cols", &[Some(&sat_layout)]),
            level_layout,
            map_layout,
            answer_layout,
            sat_layout,
        }
    }
}

/// Query slots a box test takes (`boxes.wgsl`): its standard (or clipped) Projection's, then
/// its two improved Projections'.
pub(super) const BOX_SLOTS: u32 = 3;
/// Bytes of one box (six `f64`).
pub(super) const BOX_BYTES: u64 = 48;

/// Box `b` as the shaders read a box ([`BOX_BYTES`]): min x, y, z, then max x, y, z.
pub(super) fn box_f64s(b: &crate::geom::DAabb) -> [f64; 6] {
    [b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z]
}
/// Storage buffers the box tests bind (`boxes.wgsl`): a device allowing fewer per stage
/// tests no boxes.
pub(super) const BOX_STORAGE_BUFFERS: u32 = 9;
/// A box test's source word (`box_meta` in `boxes.wgsl`) with this bit set names a box sent
/// with the submission (the rest of the word its index there); clear, a box of the resident
/// table ([`ResidentBoxes`]).
pub(super) const INLINE_BOX: u32 = 1 << 31;
/// `f64`s of one tested plane's frame for the box tests (`frames_f` in `boxes.wgsl`).
pub(super) const BOX_FRAME_F64S: usize = 12;

/// The two compute pipelines of `shaders/boxes.wgsl` (box tests' rectangles, then their
/// answers from the rectangles' answers) and their bind group layout; they need
/// `SHADER_F64`.
#[derive(Debug)]
pub(super) struct BoxPipelines {
    pub plan: wgpu::ComputePipeline,
    pub decide: wgpu::ComputePipeline,
    /// Group 0: boxes, their planes and sources, the planes' frames (`f64`, `u32`), the
    /// queries, the shapes, the answers, the counts, the resident boxes.
    pub layout: wgpu::BindGroupLayout,
    /// Bound as the resident boxes where a submission has none (one zero box).
    pub no_resident: wgpu::Buffer,
}

/// The occludee boxes kept on the device for a bake's box tests
/// ([`crate::backend::RasterBackend::upload_occludee_boxes`]): a test then sends the box's
/// index here instead of its six `f64` (each an element of six `f64`: min, then max). Each box
/// goes up the first time a test names it, from that test's box
/// ([`super::resident::ResidentTable::send_given`]), so a bake uploads at most the boxes it
/// tests, once each.
pub(super) type ResidentBoxes = super::resident::ResidentTable;

impl BoxPipelines {
    /// Compiles `source` (`shaders/boxes.wgsl` after `shaders/rounding.wgsl`) and creates its
    /// pipelines on `device`, every object labelled.
    pub fn new(device: &wgpu::Device, source: &str) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("boxes.wgsl"),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let cs = wgpu::ShaderStages::COMPUTE;
        let storage = storage_entry;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("box tests bind group layout"),
            entries: &[
                storage(0, true, BOX_BYTES),
                storage(1, true, 4),
                storage(2, true, BOX_FRAME_F64S as u64 * 8),
                storage(3, true, 16),
                storage(4, false, QUERY_BYTES),
                storage(5, false, 4),
                storage(6, true, 4),
                storage(8, false, 4),
                storage(9, true, BOX_BYTES),
                wgpu::BindGroupLayoutEntry {
                    binding: 7,
                    visibility: cs,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: NonZeroU64::new(16),
                    },
                    count: None,
                },
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("box tests pipeline layout"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = |name: &str, entry: &str| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(&format!("box tests {name} pipeline")),
                layout: Some(&pipeline_layout),
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        BoxPipelines {
            plan: pipeline("plan", "box_plan"),
            decide: pipeline("decide", "box_decide"),
            layout,
            no_resident: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("no resident occludee boxes"),
                size: BOX_BYTES,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            }),
        }
    }
}

/// Workgroups of a box pass over `boxes` boxes.
pub(super) fn box_groups(boxes: u32) -> u32 {
    boxes.div_ceil(ANSWER_WORKGROUP)
}

/// A tested plane's frame for the box tests: its `f64`s (`frames_f` in `boxes.wgsl`) and its
/// words (`frames_u`).
pub(super) fn box_frame(
    f: &crate::plane::PlaneFrame,
    improved: bool,
) -> ([f64; BOX_FRAME_F64S], [u32; 4]) {
    let c = &f.cell;
    (
        [
            c.min.x,
            c.min.y,
            c.min.z,
            c.max.x,
            c.max.y,
            c.max.z,
            f.position,
            f.rect_min.x,
            f.rect_min.y,
            f.rect_max.x,
            f.rect_max.y,
            0.0,
        ],
        [
            f.axis as u32,
            u32::from(f.positive) | u32::from(improved) << 1,
            f.width,
            f.height,
        ],
    )
}

/// The buffers of a submission's occludee tests, grown as needed and kept in the pool.
#[derive(Default)]
pub(super) struct TestBuffers {
    pub pyramid: Option<wgpu::Buffer>,
    pub params: Option<wgpu::Buffer>,
    pub planes: Option<wgpu::Buffer>,
    pub queries: Option<wgpu::Buffer>,
    pub answers: Option<wgpu::Buffer>,
    pub count: Option<wgpu::Buffer>,
    pub masks: Option<wgpu::Buffer>,
    pub steps: Option<wgpu::Buffer>,
    pub staging: Option<wgpu::Buffer>,
    /// Kept planes: their parameters, tables, summaries and the summaries' read-back.
    pub kept: Option<wgpu::Buffer>,
    pub tables: Option<wgpu::Buffer>,
    pub summary: Option<wgpu::Buffer>,
    pub summary_staging: Option<wgpu::Buffer>,
    /// Box tests: the boxes sent with the submission, each tested plane's first test then
    /// every test's source, the planes' frames, their shapes, the counts.
    pub boxes: Option<wgpu::Buffer>,
    pub box_meta: Option<wgpu::Buffer>,
    pub frames_f: Option<wgpu::Buffer>,
    pub frames_u: Option<wgpu::Buffer>,
    pub shapes: Option<wgpu::Buffer>,
    pub box_count: Option<wgpu::Buffer>,
    /// The box tests' answers, read back after the rectangle tests'.
    pub box_out: Option<wgpu::Buffer>,
}

/// Where one tested plane lies in a submission's test buffers.
#[derive(Clone, Debug)]
pub(super) struct TestedPlane {
    /// Its index among the submission's tested planes (`planes` in `shaders/hdm.wgsl`).
    pub index: u32,
    /// Its first rectangle test in the submission's query buffer, and how many (the
    /// submission's rectangle tests come first, then [`BOX_SLOTS`] query slots per box test).
    pub rects: (u32, u32),
    /// Its first box test among the submission's, and how many.
    pub boxes: (u32, u32),
    /// Its pyramid's levels (the first copies the map).
    pub levels: Vec<LevelParams>,
    /// Its slice mask's first word in the masks buffer, when the job has slices.
    pub mask: Option<u32>,
}

/// A slice mask (`0` inside the slices, `+inf` elsewhere: `prepare::slice_mask`) as bits, a
/// bit per pixel set where it is `0`, 32 pixels a word.
pub(super) fn mask_bits(mask: &crate::plane::DepthMap) -> Vec<u32> {
    let mut words = vec![0u32; mask.depth.len().div_ceil(32)];
    for (k, &m) in mask.depth.iter().enumerate() {
        debug_assert!(m == 0.0 || m == f32::INFINITY, "slice masks hold 0 or +inf");
        if m == 0.0 {
            words[k / 32] |= 1 << (k % 32);
        }
    }
    words
}

/// Workgroups of a `base` or `reduce` dispatch over a level `w × h` texels.
pub(super) fn level_groups((w, h): (u32, u32)) -> (u32, u32) {
    (w.div_ceil(LEVEL_WORKGROUP), h.div_ceil(LEVEL_WORKGROUP))
}

/// Workgroups of the answer pass over `queries` queries.
pub(super) fn answer_groups(queries: u32) -> u32 {
    queries.div_ceil(ANSWER_WORKGROUP)
}

/// A plane's entry (`Plane` in `shaders/hdm.wgsl`): width, height, levels, pyramid offset.
pub(super) fn plane_words(t: &TestedPlane) -> [u32; 4] {
    let l0 = &t.levels[0];
    [l0.dst_w, l0.dst_h, t.levels.len() as u32, l0.dst]
}

/// Byte offset of params slot `k`.
pub(super) fn param_offset(k: u32) -> u64 {
    u64::from(k) * UNIFORM_STRIDE
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `boxes.wgsl` repeats this file's constants for the box tests and binds as many storage
    /// buffers as the device is asked to allow.
    #[test]
    fn the_box_shader_agrees_with_its_constants() {
        let src = super::super::BOXES_WGSL;
        assert!(src.contains(&format!("const BOX_SLOTS: u32 = {BOX_SLOTS}u;")));
        assert!(src.contains(&format!("const INLINE_BOX: u32 = 0x{INLINE_BOX:08x}u;")));
        let storage = src
            .lines()
            .filter(|l| l.starts_with("@group(0) @binding(") && l.contains("var<storage"))
            .count();
        assert_eq!(storage as u32, BOX_STORAGE_BUFFERS);
    }

    /// The pyramid's levels and offsets follow `Hdm::build`: halving each side down to 1,
    /// level 0 its own max and min, then a max and a min per level, back to back.
    #[test]
    fn levels_are_laid_out_as_the_cpu_builds_them() {
        assert_eq!(level_sizes(4, 1), vec![(4, 1), (2, 1), (1, 1)]);
        assert_eq!(level_sizes(2, 8), vec![(2, 8), (1, 4), (1, 2), (1, 1)]);
        let p = level_params(4, 2, 100, None);
        assert_eq!(p.len(), 3);
        assert_eq!(
            (p[0].dst, p[0].dst_min, p[0].dst_w, p[0].dst_h),
            (100, 100, 4, 2)
        );
        assert_eq!(
            (p[1].src, p[1].src_min, p[1].dst, p[1].dst_min),
            (100, 100, 108, 110)
        );
        assert_eq!(
            (p[2].src, p[2].src_min, p[2].dst, p[2].dst_min),
            (108, 110, 112, 113)
        );
        assert_eq!(pyramid_floats(4, 2), 8 + 2 * 2 + 2);
        let last = p.last().unwrap();
        assert_eq!(u64::from(last.dst_min + 1 - 100), pyramid_floats(4, 2));
    }
}
