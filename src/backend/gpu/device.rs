//! The device side of the GPU backend, apart from the work: finding an adapter and creating a
//! device for [`GpuBackend::new`](super::GpuBackend::new), the failure handlers it installs,
//! what the backend needs from any device ([`DeviceLimits::check`], also for
//! [`GpuBackend::with_device`](super::GpuBackend::with_device)) and the error scopes every
//! piece of work runs in.

use super::UNIFORM_STRIDE;
use crate::backend::BackendError;
use std::sync::{Arc, Mutex};

/// Features the backend needs from a device: `R32Float` render targets with blending (the
/// Depth Map's `Min` blend).
pub(super) const REQUIRED_FEATURES: wgpu::Features = wgpu::Features::FLOAT32_BLENDABLE;
/// Features the backend's own device takes when the adapter has them: GPU timestamps at the
/// start and end of each render pass ([`super::RenderStats::pass_time`]), and `f64` in
/// shaders (ray space factorization's charts on the GPU, [`super::GpuBackend::rsf_on_gpu`]),
/// and atomics on `R32Uint` storage textures (the sampler's compute fill,
/// [`super::sampler::SamplerFill::Compute`]).
pub(super) const OPTIONAL_FEATURES: wgpu::Features = wgpu::Features::TIMESTAMP_QUERY
    .union(wgpu::Features::SHADER_F64)
    .union(wgpu::Features::TEXTURE_ATOMIC);

/// The first device loss or uncaptured error, as the error every later call returns.
pub(super) type Failure = Arc<Mutex<Option<BackendError>>>;

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

/// The instance the backend searches: the backends `WGPU_BACKEND` names, else the primary ones
/// (Vulkan, Metal, DX12).
fn new_instance() -> wgpu::Instance {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
    if desc.backends.is_empty() {
        desc.backends = wgpu::Backends::PRIMARY;
    }
    wgpu::Instance::new(desc)
}

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

/// The best usable adapter (hardware before software) of a new instance.
///
/// # Errors
/// [`BackendError::NoAdapter`], saying why, when there is none.
pub(super) fn best_adapter() -> Result<wgpu::Adapter, BackendError> {
    let instance = new_instance();
    let (adapters, rejected) = usable_adapters(&instance);
    adapters.into_iter().next().ok_or_else(|| {
        let why = if rejected.is_empty() {
            "no Vulkan, Metal or DX12 adapter is present (on Linux without a GPU, install \
             Mesa's software Vulkan driver: `apt-get install mesa-vulkan-drivers`)"
                .to_string()
        } else {
            format!("no adapter is usable: {}", rejected.join("; "))
        };
        BackendError::NoAdapter(why)
    })
}

/// The backend's own device on `adapter`: [`REQUIRED_FEATURES`], the [`OPTIONAL_FEATURES`] the
/// adapter has and every limit the adapter has, labelled `umbrasweep device`.
///
/// # Errors
/// [`BackendError::CreateDevice`] when the adapter refuses.
pub(super) fn request_device(
    adapter: &wgpu::Adapter,
) -> Result<(wgpu::Device, wgpu::Queue), BackendError> {
    pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("umbrasweep device"),
        required_features: REQUIRED_FEATURES | (adapter.features() & OPTIONAL_FEATURES),
        required_limits: adapter.limits(),
        experimental_features: wgpu::ExperimentalFeatures::disabled(),
        memory_hints: wgpu::MemoryHints::Performance,
        trace: wgpu::Trace::Off,
    }))
    .map_err(|e| BackendError::CreateDevice {
        adapter: adapter.get_info().name,
        message: e.to_string(),
    })
}

/// Records the first loss of `device`, and the first error no error scope caught, in the
/// returned slot. For the backend's own device only: both replace the device's handlers.
pub(super) fn install_failure_handlers(device: &wgpu::Device) -> Failure {
    let failure: Failure = Arc::default();
    {
        let failure = failure.clone();
        device.set_device_lost_callback(move |reason, message| {
            let mut f = failure.lock().unwrap_or_else(|e| e.into_inner());
            f.get_or_insert(BackendError::DeviceLost { reason, message });
        });
    }
    {
        let failure = failure.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            let mut f = failure.lock().unwrap_or_else(|e| e.into_inner());
            f.get_or_insert(BackendError::Uncaptured {
                message: e.to_string(),
            });
        }));
    }
    failure
}

/// What the backend reads from a device's limits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct DeviceLimits {
    /// Largest storage binding, in 16-byte words: the data of one draw chunk.
    pub max_chunk_words: usize,
    /// Alignment of storage binding offsets (at least 16 bytes).
    pub storage_align: u64,
    /// Largest buffer, in bytes.
    pub max_buffer: u64,
    /// Largest side of a 2D texture: of a Depth Map and of a reprojection's source.
    pub max_texture: u32,
}

impl DeviceLimits {
    /// The limits the backend works within on a device with `features` and `limits`.
    ///
    /// # Errors
    /// [`BackendError::MissingFeatures`] when the device lacks [`REQUIRED_FEATURES`];
    /// [`BackendError::LimitTooLow`] or [`BackendError::UniformAlignment`] when a limit is
    /// below what the backend's pipelines need (each message names it and says what to
    /// request). WebGPU's default limits ([`wgpu::Limits::default`]) are enough.
    pub fn check(features: wgpu::Features, limits: &wgpu::Limits) -> Result<Self, BackendError> {
        if !features.contains(REQUIRED_FEATURES) {
            return Err(BackendError::MissingFeatures {
                missing: REQUIRED_FEATURES - features,
            });
        }
        let storage_align = limits.min_storage_buffer_offset_alignment.max(16) as u64;
        let max_binding = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        // (limit, its value, the least the backend needs).
        let needs: [(&str, u64, u64); 11] = [
            ("max_bind_groups", limits.max_bind_groups.into(), 1),
            ("max_vertex_buffers", limits.max_vertex_buffers.into(), 1),
            (
                "max_vertex_attributes",
                limits.max_vertex_attributes.into(),
                2,
            ),
            (
                "max_inter_stage_shader_variables",
                limits.max_inter_stage_shader_variables.into(),
                3,
            ),
            (
                "max_color_attachments",
                limits.max_color_attachments.into(),
                1,
            ),
            (
                "max_uniform_buffers_per_shader_stage",
                limits.max_uniform_buffers_per_shader_stage.into(),
                1,
            ),
            (
                "max_storage_buffers_per_shader_stage",
                limits.max_storage_buffers_per_shader_stage.into(),
                1,
            ),
            (
                "max_sampled_textures_per_shader_stage",
                limits.max_sampled_textures_per_shader_stage.into(),
                1,
            ),
            (
                "max_uniform_buffer_binding_size",
                limits.max_uniform_buffer_binding_size,
                16,
            ),
            // One occluder's record and edges, and a reprojection's header and first window.
            (
                "max_storage_buffer_binding_size (and max_buffer_size)",
                max_binding,
                storage_align.max(32),
            ),
            (
                "max_texture_dimension_2d",
                limits.max_texture_dimension_2d.into(),
                1,
            ),
        ];
        for (name, value, least) in needs {
            if value < least {
                return Err(BackendError::LimitTooLow {
                    limit: name,
                    value,
                    need: least,
                });
            }
        }
        // Planes' uniforms lie UNIFORM_STRIDE bytes apart.
        let uniform_align = u64::from(limits.min_uniform_buffer_offset_alignment);
        if !UNIFORM_STRIDE.is_multiple_of(uniform_align) {
            return Err(BackendError::UniformAlignment {
                align: uniform_align,
                stride: UNIFORM_STRIDE,
            });
        }
        Ok(DeviceLimits {
            max_chunk_words: ((max_binding / storage_align * storage_align) / 16) as usize,
            storage_align,
            max_buffer: limits.max_buffer_size,
            max_texture: limits.max_texture_dimension_2d,
        })
    }
}

/// A Validation and an OutOfMemory error scope, popped together.
///
/// Fields drop in declaration order, and scopes must be popped in reverse order of their
/// pushes: `validation` (pushed last) comes first, so that a guard dropped on an early return
/// (`?`) pops cleanly instead of panicking.
pub(super) struct ErrorScopes {
    validation: wgpu::ErrorScopeGuard,
    oom: wgpu::ErrorScopeGuard,
}

impl ErrorScopes {
    /// Pushes both scopes on `device` (for this thread).
    pub fn push(device: &wgpu::Device) -> Self {
        let oom = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
        ErrorScopes { oom, validation }
    }

    /// Pops both scopes.
    ///
    /// # Errors
    /// [`BackendError::OutOfMemory`] or [`BackendError::Validation`] with the first error
    /// either caught (out of memory first).
    pub fn check(self) -> Result<(), BackendError> {
        let validation = pollster::block_on(self.validation.pop());
        let oom = pollster::block_on(self.oom.pop());
        match (oom, validation) {
            (Some(e), _) => Err(BackendError::OutOfMemory {
                message: e.to_string(),
            }),
            (None, Some(e)) => Err(BackendError::Validation {
                message: e.to_string(),
            }),
            (None, None) => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// WebGPU's defaults and the downlevel defaults are enough; the limits the backend reads
    /// come out as the backend computed them before (`max_chunk_words` rounded down to the
    /// storage alignment).
    #[test]
    fn default_limits_are_enough() {
        for limits in [wgpu::Limits::default(), wgpu::Limits::downlevel_defaults()] {
            let l = DeviceLimits::check(REQUIRED_FEATURES, &limits).expect("enough");
            assert_eq!(l.storage_align, 256);
            assert_eq!(l.max_texture, limits.max_texture_dimension_2d);
            assert_eq!(l.max_buffer, limits.max_buffer_size);
            let binding = limits
                .max_storage_buffer_binding_size
                .min(limits.max_buffer_size);
            assert_eq!(l.max_chunk_words as u64, binding / 256 * 256 / 16);
        }
        let small = wgpu::Limits {
            min_storage_buffer_offset_alignment: 32,
            max_storage_buffer_binding_size: 1000,
            ..wgpu::Limits::default()
        };
        let l = DeviceLimits::check(REQUIRED_FEATURES, &small).unwrap();
        assert_eq!((l.storage_align, l.max_chunk_words), (32, 992 / 16));
    }

    /// A device without the feature, or below a limit the pipelines need, is refused with a
    /// message naming it and saying what to request.
    #[test]
    fn missing_features_and_limits_are_named() {
        let msg = |r: Result<DeviceLimits, BackendError>| match r {
            Err(
                e @ (BackendError::MissingFeatures { .. }
                | BackendError::LimitTooLow { .. }
                | BackendError::UniformAlignment { .. }),
            ) => e.to_string(),
            other => panic!("expected an unsuitable-device error, got {other:?}"),
        };
        let m = msg(DeviceLimits::check(
            wgpu::Features::empty(),
            &wgpu::Limits::default(),
        ));
        assert!(
            m.contains("FLOAT32_BLENDABLE") && m.contains("required_features"),
            "{m}"
        );
        // WebGL2's limits: no storage buffers.
        let m = msg(DeviceLimits::check(
            REQUIRED_FEATURES,
            &wgpu::Limits::downlevel_webgl2_defaults(),
        ));
        assert!(
            m.contains("max_storage_buffers_per_shader_stage") && m.contains("required_limits"),
            "{m}"
        );
        let tiny = wgpu::Limits {
            max_storage_buffer_binding_size: 128,
            ..wgpu::Limits::default()
        };
        let m = msg(DeviceLimits::check(REQUIRED_FEATURES, &tiny));
        assert!(m.contains("max_storage_buffer_binding_size"), "{m}");
    }
}
