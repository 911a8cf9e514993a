//! Ray space factorization's charts on the GPU (`shaders/rsf.wgsl`), the twin of the CPU's
//! [`RayCharts`](crate::rsf::RayCharts) behind [`RsfCharts`].
//!
//! # Design
//! The four charts of a cell live in one storage buffer on the device (six `f32` per pixel:
//! the near and the far umbra), cleared by a compute pass when the cell starts. The traversal
//! (`bake::rsf`) alternates inserts and tests in waves; each wave is **one submission**:
//! - **insert** (if the wave has parts): the CPU packs the parts with the CPU's own per-part
//!   and per-column code ([`crate::rsf::pack`]: local segments, bounds, and per column the rows
//!   each part may write). One workgroup per column that any part may write; its threads take
//!   the column's rows, and each pixel loops over the column's parts *in the call's order* and
//!   repeats the CPU's per-pixel work (crossings at the pixel's corners, top and bottom points,
//!   fusion of floating parts, the near/far merge). Pixels are independent, so this is exactly
//!   the CPU's result of inserting the parts one after the other, without atomics on the
//!   charts. A second small pass counts the parts that wrote a pixel.
//! - **test**: one workgroup per (box, chart); its threads take the columns the box may be
//!   seen through and stop as soon as any pixel fails (the box's flag is set). Only these
//!   flags, 4 bytes per box, are read back.
//!
//! # Why it is conservative
//! Everything is computed in `f64` (the device must have [`wgpu::Features::SHADER_F64`]) with
//! the CPU's expressions, margins and rounding to `f32` — whose conservativeness
//! [`crate::rsf`] proves — so the charts are the CPU's except
//! where a driver rounds an `f64` operation differently (contracting `a·b + c` into a fused
//! multiply-add, say) and the difference crosses a threshold — a rounding error 10⁷ times
//! smaller than the margins that keep both conservative. On a device without `SHADER_F64`
//! the backend keeps the CPU's charts ([`GpuBackend::rsf_on_gpu`] says which).
//! `tests/gpu.rs` compares every pixel of both backends' charts on random scenes.
//!
//! # Measured
//! On lavapipe the charts are 25–100× slower than the CPU's (Munich: 2,149 against 66 ms per
//! cell); about a quarter of that is GPU time (timestamps), the rest waiting on the ~90
//! submissions of a cell. An insert that computes each part's crossings once per column in
//! workgroup memory (two barriers per part) was 1.9× slower there and is not used. On an
//! NVIDIA H200 the charts took 328 ms per city cell against 84 ms on the same machine's CPU
//! (402 against 56 for Munich): the submissions, each waited for, cost more than the work, so
//! the backend runs these charts only when asked ([`GpuBackend::set_rsf_on_gpu`]).

use super::GpuBackend;
use super::device::ErrorScopes;
use crate::backend::{BackendError, RsfCharts, RsfOccluder};
use crate::geom::DAabb;
use crate::rsf::pack::{self, ChartGeometry, FRAME_FLOATS, InsertPack, REC_FLOATS};
use crate::rsf::{RsfWork, Umbra};
use std::num::NonZeroU64;
use std::ops::Range;
use std::time::Instant;

/// Bytes of one parameter slot (WebGPU's largest uniform offset alignment).
const PARAM_SLOT: u64 = 256;
/// Parameter slots of one submission: clear, insert, count, test.
const PARAM_SLOTS: u64 = 4;
/// Bytes of one pixel: two umbrae of three `f32`.
const PIXEL_BYTES: u64 = 24;
/// Workgroup size of every entry point.
const WORKGROUP: u32 = 64;
/// The most workgroups along one dimension of a dispatch.
const MAX_GROUPS: u32 = 65535;

/// The compute pipelines of `shaders/rsf.wgsl` and their bind group layout, created when the
/// device has `SHADER_F64`.
#[derive(Debug)]
pub(super) struct RsfPipelines {
    layout: wgpu::BindGroupLayout,
    clear: wgpu::ComputePipeline,
    insert: wgpu::ComputePipeline,
    count: wgpu::ComputePipeline,
    test: wgpu::ComputePipeline,
}

impl RsfPipelines {
    /// Compiles the shader and creates the pipelines, every object labelled.
    ///
    /// # Errors
    /// [`BackendError::Validation`] or [`BackendError::OutOfMemory`] when the device reports one.
    pub fn new(device: &wgpu::Device) -> Result<Self, BackendError> {
        let scope = ErrorScopes::push(device);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("shaders/rsf.wgsl"),
            source: wgpu::ShaderSource::Wgsl(super::RSF_WGSL.into()),
        });
        let storage = |binding: u32, read_only: bool, min: u64| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only },
                has_dynamic_offset: false,
                min_binding_size: NonZeroU64::new(min),
            },
            count: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("rsf bind group layout"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: true,
                        min_binding_size: NonZeroU64::new(32),
                    },
                    count: None,
                },
                storage(1, true, 8),
                storage(2, true, 4),
                storage(3, false, 4),
                storage(4, false, 8),
                storage(5, false, 4),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("rsf pipeline layout"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = |entry: &'static str, label: &'static str| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(label),
                layout: Some(&pipeline_layout),
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let out = RsfPipelines {
            clear: pipeline("clear", "rsf clear pipeline"),
            insert: pipeline("insert", "rsf insert pipeline"),
            count: pipeline("count", "rsf count pipeline"),
            test: pipeline("test", "rsf test pipeline"),
            layout,
        };
        scope.check()?;
        Ok(out)
    }
}

/// One cell's device buffers, pooled in the backend between cells.
#[derive(Default)]
pub(super) struct RsfBuffers {
    charts: Option<wgpu::Buffer>,
    params: Option<wgpu::Buffer>,
    floats: Option<wgpu::Buffer>,
    ints: Option<wgpu::Buffer>,
    counters: Option<wgpu::Buffer>,
    flags: Option<wgpu::Buffer>,
    staging: Option<wgpu::Buffer>,
    /// With timestamps: a query set for the passes of one submission and the buffer it is
    /// resolved into (then copied behind the payload in `staging`).
    queries: Option<(wgpu::QuerySet, wgpu::Buffer)>,
}

/// Timestamps of one submission: a start and an end per pass, at most four passes.
const QUERIES: u32 = 2 * PARAM_SLOTS as u32;

/// The per-dispatch parameters (`Params` in the shader).
#[repr(C)]
#[derive(Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    res: u32,
    n: u32,
    rec_off: u32,
    col_off: u32,
    ent_off: u32,
    recf_off: u32,
    seg_off: u32,
    groups_x: u32,
}

/// What a submission without a test reads back.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Read {
    /// The pixels written and the occluders that wrote one.
    Counters,
    /// Every pixel of the charts.
    Charts,
}

/// The dispatch size for `groups` workgroups: `(x, y)` with `x ≤ 65535`.
fn dispatch(groups: u32) -> (u32, u32) {
    let x = groups.clamp(1, MAX_GROUPS);
    (x, groups.div_ceil(MAX_GROUPS).max(1))
}

/// One cell's charts on the GPU ([`GpuBackend::rsf_charts`]).
pub(super) struct GpuRsfCharts<'a> {
    gpu: &'a GpuBackend,
    pipelines: &'a RsfPipelines,
    geom: ChartGeometry,
    frames: Vec<f64>,
    res: u32,
    bufs: RsfBuffers,
    /// The charts have been cleared on the device.
    cleared: bool,
    /// Inserts not yet submitted (they go with the next test).
    pending: Option<InsertPack>,
}

impl<'a> GpuRsfCharts<'a> {
    /// Charts of `cell` on `gpu`, with buffers from its pool.
    pub fn new(
        gpu: &'a GpuBackend,
        pipelines: &'a RsfPipelines,
        cell: &DAabb,
        up: usize,
        resolution: u32,
    ) -> Self {
        let geom = ChartGeometry::new(cell, up, resolution);
        let bufs = gpu
            .rsf_pool
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .pop()
            .unwrap_or_default();
        GpuRsfCharts {
            gpu,
            pipelines,
            frames: geom.frame_data(),
            geom,
            res: resolution,
            bufs,
            cleared: false,
            pending: None,
        }
    }

    /// Bytes of the charts of `resolution` pixels per side.
    pub fn chart_bytes(resolution: u32) -> u64 {
        4 * u64::from(resolution) * u64::from(resolution) * PIXEL_BYTES
    }

    /// One submission: the charts cleared (first time), the pending inserts, and the test of
    /// `boxes` (each packed per chart) with its flags read back, or else what `read` says
    /// read back.
    fn submit(
        &mut self,
        boxes: Option<(&[f64], usize)>,
        read: Read,
    ) -> Result<Vec<u32>, BackendError> {
        let gpu = self.gpu;
        gpu.check_failure()?;
        let t0 = Instant::now();
        let pending = self.pending.take();
        // Floats: the frames, the inserts' record floats and segments, the boxes.
        let mut floats: Vec<f64> = self.frames.clone();
        let mut ints: Vec<u32> = Vec::new();
        let mut ins = Params {
            res: self.res,
            ..Params::default()
        };
        if let Some(p) = &pending {
            ins.recf_off = floats.len() as u32;
            floats.extend_from_slice(&p.rec_floats);
            ins.seg_off = floats.len() as u32;
            floats.extend_from_slice(&p.segs);
            ints.extend_from_slice(&p.recs);
            ins.col_off = ints.len() as u32;
            ints.extend_from_slice(&p.cols);
            ins.ent_off = ints.len() as u32;
            ints.extend_from_slice(&p.entries);
            ins.n = p.columns() as u32;
        }
        let mut test = Params {
            res: self.res,
            ..Params::default()
        };
        if let Some((b, n)) = boxes {
            test.recf_off = floats.len() as u32;
            floats.extend_from_slice(b);
            test.n = n as u32;
        }
        // Never an empty buffer (a wave without inserts).
        ints.push(0);
        let float_bytes: &[u8] = bytemuck::cast_slice(&floats);
        let int_bytes: &[u8] = bytemuck::cast_slice(&ints);
        let occluders = pending.as_ref().map_or(0, |p| p.occluders);
        let n_flags = occluders.max(boxes.map_or(0, |b| b.1)).max(1) as u64;
        let read_bytes = match (boxes, read) {
            (Some((_, n)), _) => 4 * n as u64,
            (None, Read::Counters) => 8,
            (None, Read::Charts) => Self::chart_bytes(self.res),
        };
        let scope = ErrorScopes::push(&gpu.device);
        let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let b = &mut self.bufs;
        gpu.ensure_buffer(
            &mut b.charts,
            Self::chart_bytes(self.res),
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            "rsf charts",
        )?;
        gpu.ensure_buffer(
            &mut b.params,
            PARAM_SLOT * PARAM_SLOTS,
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            "rsf parameters",
        )?;
        gpu.ensure_buffer(
            &mut b.floats,
            float_bytes.len() as u64,
            storage,
            "rsf floats",
        )?;
        gpu.ensure_buffer(&mut b.ints, int_bytes.len() as u64, storage, "rsf ints")?;
        gpu.ensure_buffer(
            &mut b.counters,
            8,
            storage | wgpu::BufferUsages::COPY_SRC,
            "rsf counters",
        )?;
        gpu.ensure_buffer(
            &mut b.flags,
            4 * n_flags,
            storage | wgpu::BufferUsages::COPY_SRC,
            "rsf flags",
        )?;
        let timed = gpu.timestamp_period.is_some();
        if timed && b.queries.is_none() {
            b.queries = Some((
                gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("rsf pass timestamps"),
                    ty: wgpu::QueryType::Timestamp,
                    count: QUERIES,
                }),
                gpu.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("rsf resolved timestamps"),
                    size: 8 * u64::from(QUERIES),
                    usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                }),
            ));
        }
        // The payload, then (with timestamps) 8 bytes per timestamp at an 8-byte offset.
        let stamps_at = read_bytes.next_multiple_of(8);
        gpu.ensure_buffer(
            &mut b.staging,
            stamps_at + 8 * u64::from(QUERIES),
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            "rsf read-back",
        )?;
        let [
            Some(charts),
            Some(params),
            Some(fbuf),
            Some(ibuf),
            Some(counters),
            Some(flags),
            Some(staging),
        ] = [
            &b.charts,
            &b.params,
            &b.floats,
            &b.ints,
            &b.counters,
            &b.flags,
            &b.staging,
        ]
        else {
            unreachable!("every buffer was just ensured");
        };
        let queue = &gpu.queue;
        queue.write_buffer(fbuf, 0, float_bytes);
        queue.write_buffer(ibuf, 0, int_bytes);
        let pixels = 4 * self.res * self.res;
        let clear = Params {
            res: self.res,
            n: pixels,
            ..Params::default()
        };
        let count = Params {
            res: self.res,
            n: occluders as u32,
            ..Params::default()
        };
        let steps: [(Params, u32); 4] = [
            (clear, pixels.div_ceil(WORKGROUP)),
            (ins, ins.n),
            (count, (occluders as u32).div_ceil(WORKGROUP)),
            (test, 4 * test.n),
        ];
        let mut uploaded = (float_bytes.len() + int_bytes.len()) as u64;
        for (k, (p, groups)) in steps.iter().enumerate() {
            let p = Params {
                groups_x: dispatch(*groups).0,
                ..*p
            };
            queue.write_buffer(params, k as u64 * PARAM_SLOT, bytemuck::bytes_of(&p));
            uploaded += 32;
        }
        let bind_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("rsf bind group"),
            layout: &self.pipelines.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: params,
                        offset: 0,
                        size: NonZeroU64::new(32),
                    }),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: fbuf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: ibuf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: charts,
                        offset: 0,
                        size: NonZeroU64::new(Self::chart_bytes(self.res)),
                    }),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: counters,
                        offset: 0,
                        size: NonZeroU64::new(8),
                    }),
                },
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: flags.as_entire_binding(),
                },
            ],
        });
        let mut encoder = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("rsf encoder"),
            });
        let mut passes = 0u32;
        let queries = b.queries.as_ref().filter(|_| timed);
        let mut pass = |encoder: &mut wgpu::CommandEncoder,
                        slot: usize,
                        pipeline: &wgpu::ComputePipeline,
                        label: &'static str| {
            let (x, y) = dispatch(steps[slot].1);
            let mut cp = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(label),
                timestamp_writes: queries.map(|(set, _)| wgpu::ComputePassTimestampWrites {
                    query_set: set,
                    beginning_of_pass_write_index: Some(2 * passes),
                    end_of_pass_write_index: Some(2 * passes + 1),
                }),
            });
            cp.set_pipeline(pipeline);
            cp.set_bind_group(0, &bind_group, &[(slot as u64 * PARAM_SLOT) as u32]);
            cp.dispatch_workgroups(x, y, 1);
            passes += 1;
        };
        let pl = self.pipelines;
        if !self.cleared {
            encoder.clear_buffer(counters, 0, None);
            pass(&mut encoder, 0, &pl.clear, "rsf clear pass");
            self.cleared = true;
        }
        if ins.n > 0 {
            encoder.clear_buffer(flags, 0, Some(4 * occluders as u64));
            pass(&mut encoder, 1, &pl.insert, "rsf insert pass");
            pass(&mut encoder, 2, &pl.count, "rsf count pass");
        }
        if test.n > 0 {
            encoder.clear_buffer(flags, 0, Some(4 * u64::from(test.n)));
            pass(&mut encoder, 3, &pl.test, "rsf test pass");
            encoder.copy_buffer_to_buffer(flags, 0, staging, 0, read_bytes);
        } else if read == Read::Counters {
            encoder.copy_buffer_to_buffer(counters, 0, staging, 0, read_bytes);
        } else {
            encoder.copy_buffer_to_buffer(charts, 0, staging, 0, read_bytes);
        }
        let stamp_bytes = if let Some((set, resolved)) = queries
            && passes > 0
        {
            encoder.resolve_query_set(set, 0..2 * passes, resolved, 0);
            let n = 16 * u64::from(passes);
            encoder.copy_buffer_to_buffer(resolved, 0, staging, stamps_at, n);
            n
        } else {
            0
        };
        let map_bytes = if stamp_bytes > 0 {
            stamps_at + stamp_bytes
        } else {
            read_bytes
        };
        let submission = gpu.submit_commands(encoder.finish());
        scope.check()?;
        let (tx, rx) = std::sync::mpsc::channel();
        staging
            .slice(..map_bytes)
            .map_async(wgpu::MapMode::Read, move |r| {
                let _ = tx.send(r);
            });
        gpu.poll_until(&submission, "a ray-space wave", || match rx.try_recv() {
            Ok(r) => r.map(|()| true).map_err(|e| BackendError::ReadBack {
                step: "ray-space flags",
                message: e.to_string(),
            }),
            Err(_) => Ok(false),
        })?;
        let (out, ticks): (Vec<u32>, u64) = {
            let view = staging.slice(..map_bytes).get_mapped_range().map_err(|e| {
                BackendError::ReadBack {
                    step: "ray-space flags mapping",
                    message: e.to_string(),
                }
            })?;
            let out = view[..read_bytes as usize]
                .chunks_exact(4)
                .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect();
            let stamps: Vec<u64> = view[stamps_at.min(map_bytes) as usize..]
                .chunks_exact(8)
                .map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes")))
                .collect();
            let ticks = stamps
                .chunks_exact(2)
                .map(|p| p[1].saturating_sub(p[0]))
                .sum();
            (out, ticks)
        };
        staging.unmap();
        let timed_passes = if stamp_bytes > 0 { passes as usize } else { 0 };
        gpu.add_totals(&super::RenderStats {
            submissions: 1,
            passes: passes as usize,
            pass_time: std::time::Duration::from_nanos(
                (ticks as f64 * gpu.timestamp_period.unwrap_or(0.0)).round() as u64,
            ),
            timed_passes,
            bytes_uploaded: uploaded,
            bytes_read_back: map_bytes,
            gpu: t0.elapsed(),
            total: t0.elapsed(),
            ..super::RenderStats::default()
        });
        Ok(out)
    }
}

impl Drop for GpuRsfCharts<'_> {
    fn drop(&mut self) {
        let bufs = std::mem::take(&mut self.bufs);
        self.gpu
            .rsf_pool
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(bufs);
    }
}

impl RsfCharts for GpuRsfCharts<'_> {
    fn insert(&mut self, occluders: &[RsfOccluder]) -> Result<(), BackendError> {
        if occluders.is_empty() {
            return Ok(());
        }
        if self.pending.is_some() {
            // Two insert calls in a row (a dump's last parts): the first goes alone.
            self.submit(None, Read::Counters)?;
        }
        let pack = self
            .geom
            .pack_inserts(occluders.iter().map(|o| (o.points.as_ref(), o.hull_edges)));
        self.pending = Some(pack);
        Ok(())
    }

    fn hidden(
        &mut self,
        boxes: &[DAabb],
        groups: &[Range<usize>],
    ) -> Result<Vec<bool>, BackendError> {
        let mut packed = Vec::with_capacity(boxes.len() * 4 * pack::BOX_FLOATS);
        self.geom.pack_boxes(boxes, &mut packed);
        let visible = if boxes.is_empty() {
            Vec::new()
        } else {
            self.submit(Some((&packed, boxes.len())), Read::Counters)?
        };
        Ok(groups
            .iter()
            .map(|r| {
                visible[r.start] == 0 || {
                    let pieces = &visible[r.start + 1..r.end];
                    !pieces.is_empty() && pieces.iter().all(|&v| v == 0)
                }
            })
            .collect())
    }

    fn work(&mut self) -> Result<RsfWork, BackendError> {
        let c = self.submit(None, Read::Counters)?;
        Ok(RsfWork {
            polygons: c[1] as usize,
            pixels: c[0] as usize,
        })
    }

    fn snapshot(&mut self) -> Result<Vec<[Umbra; 2]>, BackendError> {
        let w = self.submit(None, Read::Charts)?;
        let f = |k: usize| f32::from_bits(w[k]);
        Ok((0..w.len() / 6)
            .map(|p| {
                let k = 6 * p;
                [
                    Umbra {
                        slope: f(k),
                        guard: f(k + 1),
                        base: f(k + 2),
                    },
                    Umbra {
                        slope: f(k + 3),
                        guard: f(k + 4),
                        base: f(k + 5),
                    },
                ]
            })
            .collect())
    }
}

// The shader indexes the packed arrays with these strides as literals.
const _: () = assert!(
    FRAME_FLOATS == 8
        && REC_FLOATS == 4
        && pack::REC_INTS == 4
        && pack::COL_INTS == 6
        && pack::ENTRY_INTS == 3
        && pack::BOX_FLOATS == 6
);
