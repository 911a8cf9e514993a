//! The backend's device resources that do not depend on the work: the render pipelines
//! (occluder Projections, reprojections) and their bind group layouts, created once per device
//! by [`Pipelines::new`], and, on devices with `SHADER_F64`, the views pass and the counted
//! draw of [`GpuProjection::Counting`](super::GpuProjection::Counting) ([`ViewPipelines`]).

use super::device::ErrorScopes;
use super::setup::Vertex;
use super::{PROJECTION_WGSL, REPROJECT_WGSL, VIEWS_WGSL};
use crate::backend::BackendError;
use std::num::NonZeroU64;

/// The blend of every pass into a Depth Map: the minimum of the fragment's and the target's
/// Depth.
const MIN_BLEND: wgpu::BlendComponent = wgpu::BlendComponent {
    src_factor: wgpu::BlendFactor::One,
    dst_factor: wgpu::BlendFactor::One,
    operation: wgpu::BlendOperation::Min,
};

/// Both render pipelines of the backend and their bind group layouts.
#[derive(Debug)]
pub(super) struct Pipelines {
    /// The occluders' draw (`shaders/projection.wgsl`).
    pub projection: wgpu::RenderPipeline,
    /// Its bind group: the plane's uniforms and a chunk of its records and edges.
    pub projection_layout: wgpu::BindGroupLayout,
    /// The reprojections' draw into the plane's target (`shaders/reproject.wgsl`).
    pub reproject: wgpu::RenderPipeline,
    /// Its bind group: the reprojection's windows and its summed-area table.
    pub reproject_layout: wgpu::BindGroupLayout,
}

impl Pipelines {
    /// Compiles the shaders and creates both pipelines on `device`, every object labelled.
    ///
    /// # Errors
    /// [`BackendError::Validation`] or [`BackendError::OutOfMemory`] when the device reports one.
    pub fn new(device: &wgpu::Device) -> Result<Self, BackendError> {
        let scope = ErrorScopes::push(device);
        let (projection, projection_layout) = projection_pipeline(device);
        let (reproject, reproject_layout) = reproject_pipeline(device);
        scope.check()?;
        Ok(Pipelines {
            projection,
            projection_layout,
            reproject,
            reproject_layout,
        })
    }
}

/// The pipelines of [`GpuProjection::Counting`](super::GpuProjection::Counting): the compute
/// pass that projects every occluder's views and writes its record (`shaders/views.wgsl`), and
/// the instanced draw that counts them per fragment (`vs_counted` and `fs_main` in
/// `shaders/projection.wgsl`).
#[derive(Debug)]
pub(super) struct ViewPipelines {
    /// The views pass.
    pub views: wgpu::ComputePipeline,
    /// Its bind group: points, occluders, plane frames (f64 and u32), records (written), the
    /// resident parts' points.
    pub views_layout: wgpu::BindGroupLayout,
    /// The counted draw.
    pub counted: wgpu::RenderPipeline,
    /// Its bind group: the plane's uniforms, the records and the occluders.
    pub counted_layout: wgpu::BindGroupLayout,
    /// Bound as the resident parts' points where a wave has none.
    pub no_parts: wgpu::Buffer,
}

impl ViewPipelines {
    /// Compiles both shaders and creates both pipelines on `device` (which must have
    /// `SHADER_F64`), every object labelled.
    ///
    /// # Errors
    /// [`BackendError::Validation`] or [`BackendError::OutOfMemory`] when the device reports one.
    pub fn new(device: &wgpu::Device) -> Result<Self, BackendError> {
        let scope = ErrorScopes::push(device);
        let storage = |binding: u32, read_only: bool, visibility: wgpu::ShaderStages| {
            wgpu::BindGroupLayoutEntry {
                binding,
                visibility,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only },
                    has_dynamic_offset: false,
                    min_binding_size: NonZeroU64::new(16),
                },
                count: None,
            }
        };
        let cs = wgpu::ShaderStages::COMPUTE;
        let views_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("views bind group layout"),
            entries: &[
                storage(0, true, cs),
                storage(1, true, cs),
                storage(2, true, cs),
                storage(3, true, cs),
                storage(4, false, cs),
                storage(5, true, cs),
            ],
        });
        let views_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("shaders/views.wgsl"),
            source: wgpu::ShaderSource::Wgsl(VIEWS_WGSL.into()),
        });
        let views = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("views pipeline"),
            layout: Some(
                &device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                    label: Some("views pipeline layout"),
                    bind_group_layouts: &[Some(&views_layout)],
                    immediate_size: 0,
                }),
            ),
            module: &views_module,
            entry_point: Some("views"),
            compilation_options: Default::default(),
            cache: None,
        });
        let vf = wgpu::ShaderStages::VERTEX_FRAGMENT;
        let counted_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("counted bind group layout"),
            entries: &[
                plane_uniforms_entry(),
                storage(1, true, vf),
                storage(2, true, wgpu::ShaderStages::VERTEX),
            ],
        });
        let counted_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("shaders/projection.wgsl (counted)"),
            source: wgpu::ShaderSource::Wgsl(PROJECTION_WGSL.into()),
        });
        let counted = depth_map_pipeline(
            device,
            "counted",
            &counted_layout,
            &counted_module,
            ("vs_counted", "fs_main"),
            &[],
        );
        let no_parts = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("no resident occluder points"),
            size: 32,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        scope.check()?;

        Ok(ViewPipelines {
            views,
            views_layout,
            counted,
            counted_layout,
            no_parts,
        })
    }
}

/// The colour target of every pass into a Depth Map: `R32Float`, red only, blended with
/// [`MIN_BLEND`].
pub(super) fn depth_min_target() -> wgpu::ColorTargetState {
    wgpu::ColorTargetState {
        format: wgpu::TextureFormat::R32Float,
        blend: Some(wgpu::BlendState {
            color: MIN_BLEND,
            alpha: MIN_BLEND,
        }),
        write_mask: wgpu::ColorWrites::RED,
    }
}

/// The occluders' pipeline (a triangle list of [`Vertex`] into the `R32Float` Depth Map) and
/// its bind group layout: the plane's uniforms (vertex stage) and the records and edges
/// (storage, both stages).
fn projection_pipeline(device: &wgpu::Device) -> (wgpu::RenderPipeline, wgpu::BindGroupLayout) {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("shaders/projection.wgsl"),
        source: wgpu::ShaderSource::Wgsl(PROJECTION_WGSL.into()),
    });
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("projection bind group layout"),
        entries: &[
            plane_uniforms_entry(),
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
    let attributes = wgpu::vertex_attr_array![0 => Float32x2, 1 => Uint32];
    let pipeline = depth_map_pipeline(
        device,
        "projection",
        &layout,
        &module,
        ("vs_main", "fs_main"),
        &[Some(wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<Vertex>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &attributes,
        })],
    );
    (pipeline, layout)
}

/// The reprojections' pipeline (a fullscreen triangle into the `R32Float` Depth Map) and its
/// bind group layout: the windows (storage) and the summed-area table.
fn reproject_pipeline(device: &wgpu::Device) -> (wgpu::RenderPipeline, wgpu::BindGroupLayout) {
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
    let pipeline = depth_map_pipeline(
        device,
        "reprojection",
        &layout,
        &module,
        ("vs_fullscreen", "fs_reproject"),
        &[],
    );
    (pipeline, layout)
}

/// Binding 0 of the occluder draws: the plane's uniforms (pixel to NDC scale), vertex stage.
fn plane_uniforms_entry() -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding: 0,
        visibility: wgpu::ShaderStages::VERTEX,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: NonZeroU64::new(16),
        },
        count: None,
    }
}

/// A render pipeline into an `R32Float` Depth Map ([`depth_min_target`]): a triangle list from
/// `entries` (vertex and fragment entry points) of `module`, with one bind group of `layout`,
/// labelled `name pipeline` (and its layout `name pipeline layout`).
pub(super) fn depth_map_pipeline(
    device: &wgpu::Device,
    name: &str,
    layout: &wgpu::BindGroupLayout,
    module: &wgpu::ShaderModule,
    (vs, fs): (&str, &str),
    buffers: &[Option<wgpu::VertexBufferLayout>],
) -> wgpu::RenderPipeline {
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(&format!("{name} pipeline layout")),
        bind_group_layouts: &[Some(layout)],
        immediate_size: 0,
    });
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(&format!("{name} pipeline")),
        layout: Some(&pipeline_layout),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some(vs),
            compilation_options: Default::default(),
            buffers,
        },
        primitive: wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::TriangleList,
            cull_mode: None,
            ..Default::default()
        },
        depth_stencil: None,
        multisample: wgpu::MultisampleState::default(),
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some(fs),
            compilation_options: Default::default(),
            targets: &[Some(depth_min_target())],
        }),
        multiview_mask: None,
        cache: None,
    })
}
