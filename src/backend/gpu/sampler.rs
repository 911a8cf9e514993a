//! The shrunk-occluder sampler's hemicube on the GPU (`shaders/sampler.wgsl`), the twin of the
//! CPU's [`Hemicube`]: [`GpuSampler`].
//!
//! # Design
//! The CPU keeps the traversal and the per-polygon work ([`Hemicube::record`]: the same code
//! as its own draws, so edges, shrinks, depths and pixel bounds are the CPU's to the bit) and
//! the occludees' per-view parts ([`Hemicube::box_rects`]); the GPU does the per-pixel work,
//! which is where the CPU spends its time (a render of the fine forest reaches ~281 k
//! polygons and spends most of its time in the pixels of the ~23 k it draws). One submission
//! per sample point: five render passes (one per view, one instance per draw) into an
//! `R32Float` array at 8× the view's resolution, one fragment per sub-pixel, `Min` blended;
//! a compute pass taking each pixel's largest sub-pixel depth; a compute pass testing the
//! boxes' parts, one workgroup each; only a flag per box is read back.
//!
//! # Why it is conservative, and what it answers
//! A fragment repeats the CPU's per-pixel decision for its pixel (corner tests in `f32` with
//! the CPU's table of `√(u²+v²+1)` and margin, the sub-pixel's bit of the CPU's mask in `f64`,
//! per-pixel plane depths in `f64` rounded up as the CPU rounds them), so it covers a
//! sub-pixel only where the CPU's argument ([`crate::sampler`]) covers it. Each sub-pixel keeps
//! its own nearest depth, where the CPU keeps at most eight partial layers per pixel and
//! merges the two farthest (which only loses): the GPU hides every box the CPU hides, and a
//! few more where pixels gather more than eight depths (about 1 % more objects hidden from a
//! point of the fine forest: 32 layers on the CPU hide 3,702 objects against 3,659 with 8,
//! `examples/sampler_points`, 12 points, ε 0.05, 1,024 px). A driver rounding an `f64`
//! operation differently (a fused multiply-add) moves a decision only where a test is within
//! a rounding error of a margin 10⁷ times larger. Textured card triangles are left out
//! ([`Hemicube::record`]), which only uncovers pixels.
//!
//! # Not yet
//! This is the twin of one render; the sampler's driver (`bake::sampling`) still renders on
//! the CPU. Still to come: the per-polygon work in a compute pass (the CPU's share), several
//! sample points per submission, and the pieces' and triangles' tests.

use super::GpuBackend;
use super::device::ErrorScopes;
use crate::backend::BackendError;
use crate::geom::DAabb;
use crate::sampler::{BoxRect, DrawList, Hemicube, RenderStats, SampleOccluders};
use glam::DVec3;
use std::num::NonZeroU64;

/// Bytes of one parameter slot (WebGPU's largest uniform offset alignment).
const PARAM_SLOT: u64 = 256;
/// Parameter slots: the five views' fills, the reduction, the test.
const SLOTS: u64 = 7;
/// Workgroup size of the compute entry points.
const WORKGROUP: u32 = 64;
/// The most workgroups along one dimension of a dispatch.
const MAX_GROUPS: u32 = 65535;
/// Sub-pixels per pixel side.
const SUB: u32 = 8;
/// `NO_PLANE` of the shader.
const NO_PLANE: u32 = u32::MAX;

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
    pad: [u32; 2],
}

/// The dispatch size for `groups` workgroups: `(x, y)` with `x ≤ 65535`.
fn dispatch(groups: u32) -> (u32, u32) {
    let x = groups.clamp(1, MAX_GROUPS);
    (x, groups.div_ceil(MAX_GROUPS).max(1))
}

/// The sampler's hemicube on a [`GpuBackend`]'s device: the CPU's [`Hemicube`] records, the
/// device draws and tests (module docs).
///
/// ```no_run
/// use glam::DVec3;
/// use umbrasweep::backend::gpu::{GpuBackend, sampler::GpuSampler};
/// use umbrasweep::geom::DAabb;
/// use umbrasweep::sampler::SampleOccluders;
///
/// let gpu = GpuBackend::new()?;
/// let leaf = vec![DVec3::new(-1.0, -1.0, 5.0), DVec3::new(1.0, -1.0, 5.0), DVec3::new(0.0, 1.0, 5.0)];
/// let occ = SampleOccluders::from_polygons(&[(leaf, 0)]);
/// let boxes = [DAabb { min: DVec3::new(-0.1, -0.1, 9.0), max: DVec3::new(0.1, 0.1, 9.2) }];
/// let mut hc = GpuSampler::new(&gpu, 64)?;
/// hc.begin(DVec3::ZERO, 2, 1.0, 0.01, &boxes);
/// hc.draw(&occ);
/// assert_eq!(hc.test_boxes(&boxes)?, vec![true]);
/// # Ok::<(), umbrasweep::backend::BackendError>(())
/// ```
pub struct GpuSampler<'a> {
    gpu: &'a GpuBackend,
    hc: Hemicube,
    list: DrawList,
    fill_layout: wgpu::BindGroupLayout,
    test_layout: wgpu::BindGroupLayout,
    fill: wgpu::RenderPipeline,
    reduce: wgpu::ComputePipeline,
    test: wgpu::ComputePipeline,
    /// The sub-pixel depths: five layers of `8R × 8R` (the sides use the lower half); kept
    /// for its views.
    _fine: wgpu::Texture,
    fine_layers: Vec<wgpu::TextureView>,
    fine_all: wgpu::TextureView,
    params: wgpu::Buffer,
    norms: wgpu::Buffer,
    pixmax: wgpu::Buffer,
    draws: Option<wgpu::Buffer>,
    edges: Option<wgpu::Buffer>,
    planes: Option<wgpu::Buffer>,
    parts_u: Option<wgpu::Buffer>,
    parts_f: Option<wgpu::Buffer>,
    flags: Option<wgpu::Buffer>,
    staging: Option<wgpu::Buffer>,
}

impl std::fmt::Debug for GpuSampler<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuSampler")
            .field("resolution", &self.hc.resolution())
            .finish_non_exhaustive()
    }
}

impl<'a> GpuSampler<'a> {
    /// A hemicube of `res` pixels across each view (rounded up to a multiple of 16, as
    /// [`Hemicube::new`]) on `gpu`'s device.
    ///
    /// # Errors
    /// * [`BackendError::MissingFeatures`] when the device lacks `SHADER_F64` (the sub-pixel
    ///   masks and plane depths are the CPU's `f64` expressions);
    /// * [`BackendError::PlaneSize`] when `8 × res` exceeds the device's largest texture side;
    /// * [`BackendError::Validation`] or [`BackendError::OutOfMemory`] when the device reports
    ///   one while the pipelines and textures are created.
    pub fn new(gpu: &'a GpuBackend, res: u32) -> Result<Self, BackendError> {
        gpu.check_failure()?;
        let device = &gpu.device;
        if !device.features().contains(wgpu::Features::SHADER_F64) {
            return Err(BackendError::MissingFeatures {
                missing: wgpu::Features::SHADER_F64,
            });
        }
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
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("shaders/sampler.wgsl"),
            source: wgpu::ShaderSource::Wgsl(super::SAMPLER_WGSL.into()),
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
        let vf = wgpu::ShaderStages::VERTEX_FRAGMENT;
        let fill_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("sampler fill bind group layout"),
            entries: &[
                uniform(vf),
                storage(1, vf, true),
                storage(2, vf, true),
                storage(3, vf, true),
                storage(4, vf, true),
            ],
        });
        let cs = wgpu::ShaderStages::COMPUTE;
        let test_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("sampler test bind group layout"),
            entries: &[
                uniform(cs),
                wgpu::BindGroupLayoutEntry {
                    binding: 5,
                    visibility: cs,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2Array,
                        multisampled: false,
                    },
                    count: None,
                },
                storage(6, cs, false),
                storage(7, cs, true),
                storage(8, cs, true),
                storage(9, cs, false),
            ],
        });
        let fill_pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("sampler fill pipeline layout"),
            bind_group_layouts: &[Some(&fill_layout)],
            immediate_size: 0,
        });
        let test_pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("sampler test pipeline layout"),
            bind_group_layouts: &[Some(&test_layout)],
            immediate_size: 0,
        });
        let fill = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("sampler fill pipeline"),
            layout: Some(&fill_pl),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_fill"),
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
                entry_point: Some("fs_fill"),
                compilation_options: Default::default(),
                targets: &[Some(super::pipelines::depth_min_target())],
            }),
            multiview_mask: None,
            cache: None,
        });
        let compute = |entry: &'static str, label: &'static str| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(label),
                layout: Some(&test_pl),
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let reduce = compute("reduce", "sampler reduce pipeline");
        let test = compute("test", "sampler test pipeline");
        let fine = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("sampler sub-pixel depths"),
            size: wgpu::Extent3d {
                width: side,
                height: side,
                depth_or_array_layers: 5,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::R32Float,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        });
        let fine_layers = (0..5)
            .map(|k| {
                fine.create_view(&wgpu::TextureViewDescriptor {
                    label: Some("sampler view layer"),
                    dimension: Some(wgpu::TextureViewDimension::D2),
                    base_array_layer: k,
                    array_layer_count: Some(1),
                    ..Default::default()
                })
            })
            .collect();
        let fine_all = fine.create_view(&wgpu::TextureViewDescriptor {
            label: Some("sampler sub-pixel depths (all views)"),
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let (front, sides) = hc.corner_norms();
        let norm_data: Vec<f32> = front.iter().chain(sides).copied().collect();
        let norms = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("sampler corner norms"),
            size: 4 * norm_data.len() as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        gpu.queue
            .write_buffer(&norms, 0, bytemuck::cast_slice(&norm_data));
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("sampler parameters"),
            size: PARAM_SLOT * SLOTS,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let pixmax = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("sampler pixel depths"),
            size: 4 * 5 * u64::from(r) * u64::from(r),
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        scope.check()?;
        Ok(GpuSampler {
            gpu,
            hc,
            list: DrawList::default(),
            fill_layout,
            test_layout,
            fill,
            reduce,
            test,
            _fine: fine,
            fine_layers,
            fine_all,
            params,
            norms,
            pixmax,
            draws: None,
            edges: None,
            planes: None,
            parts_u: None,
            parts_f: None,
            flags: None,
            staging: None,
        })
    }

    /// The CPU hemicube that records (for its settings: [`Hemicube::set_subpixel`],
    /// [`Hemicube::set_depth_bounded`]).
    pub fn hemicube(&mut self) -> &mut Hemicube {
        &mut self.hc
    }

    /// [`Hemicube::begin`].
    pub fn begin(&mut self, eye: DVec3, axis: usize, sign: f64, eps: f64, boxes: &[DAabb]) {
        self.list = DrawList::default();
        self.hc.begin(eye, axis, sign, eps, boxes);
    }

    /// [`Hemicube::begin_patch`].
    pub fn begin_patch(
        &mut self,
        eye: DVec3,
        axis: usize,
        sign: f64,
        half: [f64; 2],
        boxes: &[DAabb],
    ) {
        self.list = DrawList::default();
        self.hc.begin_patch(eye, axis, sign, half, boxes);
    }

    /// Records the polygons of `occ` for the device ([`Hemicube::record`]); they are drawn by
    /// the next [`GpuSampler::test_boxes`].
    pub fn draw(&mut self, occ: &SampleOccluders) -> RenderStats {
        let (list, st) = self.hc.record(occ);
        self.list = list;
        st
    }

    /// Draws what [`GpuSampler::draw`] recorded and tests `boxes` (each given to the last
    /// `begin`, or inside their pixels) as [`Hemicube::test_box`] does: true for a box hidden
    /// from every point of the ball (or rectangle), looking out through the face.
    ///
    /// # Errors
    /// The device's failures ([`BackendError::device_failed`]), and
    /// [`BackendError::BufferTooLarge`] for more draws or boxes than a buffer holds.
    pub fn test_boxes(&mut self, boxes: &[DAabb]) -> Result<Vec<bool>, BackendError> {
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
        // The draws, view by view.
        let mut order: Vec<usize> = (0..self.list.draws.len()).collect();
        order.sort_by_key(|&d| self.list.draws[d].view);
        let mut draws: Vec<[u32; 4]> = Vec::with_capacity(2 * order.len() + 2);
        let mut planes: Vec<f64> = Vec::new();
        let mut ranges = [(0u32, 0u32); 5];
        for &d in &order {
            let dr = &self.list.draws[d];
            let k = usize::from(dr.view);
            let idx = (draws.len() / 2) as u32;
            if ranges[k].1 == 0 {
                ranges[k].0 = idx;
            }
            ranges[k].1 += 1;
            let plane = match dr.plane {
                Some(p) => {
                    planes.extend_from_slice(&p);
                    (planes.len() / 4 - 1) as u32
                }
                None => NO_PLANE,
            };
            draws.push([
                dr.edges[0],
                (dr.edges[1] - dr.edges[0]) | u32::from(dr.thin) << 16,
                dr.z.to_bits(),
                plane,
            ]);
            draws.push([dr.px[0] | dr.px[1] << 16, dr.px[2] | dr.px[3] << 16, 0, 0]);
        }
        let n_parts = parts_u.len() as u32;
        // Never an empty buffer.
        draws.push([0; 4]);
        planes.push(0.0);
        parts_u.push([0; 4]);
        parts_f.push(0.0);
        let mut edges = self.list.edges.clone();
        edges.push([0.0; 4]);
        let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let upload = [
            (
                &mut self.draws,
                bytemuck::cast_slice::<_, u8>(&draws),
                "sampler draws",
            ),
            (
                &mut self.edges,
                bytemuck::cast_slice(&edges),
                "sampler edges",
            ),
            (
                &mut self.planes,
                bytemuck::cast_slice(&planes),
                "sampler planes",
            ),
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
        ];
        let scope = ErrorScopes::push(&gpu.device);
        let mut uploaded = 0u64;
        for (slot, bytes, label) in upload {
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
        gpu.ensure_buffer(
            &mut self.staging,
            flag_bytes,
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            "sampler flags read-back",
        )?;
        let (
            Some(draws_b),
            Some(edges_b),
            Some(planes_b),
            Some(parts_u_b),
            Some(parts_f_b),
            Some(flags_b),
            Some(staging),
        ) = (
            &self.draws,
            &self.edges,
            &self.planes,
            &self.parts_u,
            &self.parts_f,
            &self.flags,
            &self.staging,
        )
        else {
            unreachable!("every buffer was just ensured");
        };
        gpu.queue
            .write_buffer(flags_b, 0, bytemuck::cast_slice(&open));
        let subpixel = u32::from(self.hc.subpixel());
        for k in 0..5u32 {
            let p = Params {
                res,
                view: k,
                subpixel,
                rows: if k == 0 { res } else { res / 2 },
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
        uploaded += SLOTS * std::mem::size_of::<Params>() as u64 + flag_bytes;
        let param_binding = wgpu::BindingResource::Buffer(wgpu::BufferBinding {
            buffer: &self.params,
            offset: 0,
            size: NonZeroU64::new(std::mem::size_of::<Params>() as u64),
        });
        let fill_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("sampler fill bind group"),
            layout: &self.fill_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: param_binding.clone(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: draws_b.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: edges_b.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: planes_b.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: self.norms.as_entire_binding(),
                },
            ],
        });
        let test_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("sampler test bind group"),
            layout: &self.test_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: param_binding,
                },
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: wgpu::BindingResource::TextureView(&self.fine_all),
                },
                wgpu::BindGroupEntry {
                    binding: 6,
                    resource: self.pixmax.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 7,
                    resource: parts_u_b.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 8,
                    resource: parts_f_b.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 9,
                    resource: flags_b.as_entire_binding(),
                },
            ],
        });
        let mut encoder = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("sampler encoder"),
            });
        for (k, &(first, count)) in ranges.iter().enumerate() {
            let rows = if k == 0 { res } else { res / 2 };
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("sampler fill pass"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &self.fine_layers[k],
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
            if count > 0 {
                pass.set_viewport(0.0, 0.0, (SUB * res) as f32, (SUB * rows) as f32, 0.0, 1.0);
                pass.set_pipeline(&self.fill);
                pass.set_bind_group(0, &fill_group, &[(k as u64 * PARAM_SLOT) as u32]);
                pass.draw(0..6, first..first + count);
            }
        }
        {
            let mut cp = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("sampler reduce pass"),
                timestamp_writes: None,
            });
            cp.set_pipeline(&self.reduce);
            cp.set_bind_group(0, &test_group, &[(5 * PARAM_SLOT) as u32]);
            cp.dispatch_workgroups(reduce_groups.0, reduce_groups.1, 1);
        }
        if n_parts > 0 {
            let mut cp = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("sampler test pass"),
                timestamp_writes: None,
            });
            cp.set_pipeline(&self.test);
            cp.set_bind_group(0, &test_group, &[(6 * PARAM_SLOT) as u32]);
            cp.dispatch_workgroups(test_groups.0, test_groups.1, 1);
        }
        encoder.copy_buffer_to_buffer(flags_b, 0, staging, 0, flag_bytes);
        let submission = gpu.queue.submit([encoder.finish()]);
        scope.check()?;
        let (tx, rx) = std::sync::mpsc::channel();
        staging
            .slice(..flag_bytes)
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
        let hidden: Vec<bool> = {
            let view = staging
                .slice(..flag_bytes)
                .get_mapped_range()
                .map_err(|e| BackendError::ReadBack {
                    step: "sampler flags mapping",
                    message: e.to_string(),
                })?;
            view.chunks_exact(4)
                .take(boxes.len())
                .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]) == 0)
                .collect()
        };
        staging.unmap();
        gpu.add_totals(&super::RenderStats {
            submissions: 1,
            passes: 7,
            bytes_uploaded: uploaded,
            bytes_read_back: flag_bytes,
            ..super::RenderStats::default()
        });
        Ok(hidden)
    }
}
