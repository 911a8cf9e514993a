//! The GPU section of a `render` call. [`plan_waves`] splits the planes that need the GPU into
//! *waves* (submissions) bounded in memory; [`GpuBackend::render_wave`] runs one wave in named
//! steps:
//!
//! 1. layout ([`WaveLayout::new`]): every plane's place in the shared buffers and the pools
//!    (one [`PlaneLayout`] per plane) — arithmetic only;
//! 2. allocate ([`GpuBackend::allocate`]): grow the shared buffers, add pooled targets and
//!    tables;
//! 3. upload ([`GpuBackend::upload`]): geometry, records and edges, windows, uniforms, tables;
//! 4. encode ([`GpuBackend::encode`]): per plane one render pass and one copy into its
//!    read-back buffer, in one command buffer;
//! 5. submit ([`GpuBackend::submit`]) and map every read-back buffer;
//! 6. wait ([`GpuBackend::wait`]), polling with a timeout;
//! 7. read back ([`read_back`]): the Depth Maps, with the slice masks merged.

use super::device::{DeviceLimits, ErrorScopes};
use super::prepare::{Prepared, merge_mask};
use super::setup::Vertex;
use super::{GpuBackend, RenderStats, UNIFORM_STRIDE};
use crate::backend::BackendError;
use crate::plane::{DepthMap, PlaneJob};
use std::collections::HashMap;
use std::num::NonZeroU64;
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// Bytes of render targets + staging buffers one submission may use.
const TARGET_BUDGET: u64 = 256 << 20;
/// Bytes of vertex + record/edge data one submission may use (also capped by the device).
const DATA_BUDGET: u64 = 512 << 20;
/// How long one poll blocks before the device-lost flag and the deadline are checked again.
const POLL_SLICE: Duration = Duration::from_millis(250);
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
    /// Per map size `(width, height)`.
    targets: HashMap<(u32, u32), Vec<Target>>,
    /// Reprojections' summed-area tables, one per reprojection of a submission, per source
    /// size.
    tables: HashMap<(u32, u32), Vec<SweepTable>>,
    /// Timestamp query sets, each for [`TIMESTAMPS_PER_SET`] / 2 render passes of a
    /// submission (with timestamps only).
    timestamps: Vec<TimestampSet>,
}

/// One plane's render target and its read-back buffer.
struct Target {
    view: wgpu::TextureView,
    texture: wgpu::Texture,
    staging: wgpu::Buffer,
    padded_row: u32,
}

/// One reprojection's summed-area table (see [`SweepSetup::table`]).
///
/// [`SweepSetup::table`]: super::prepare::SweepSetup::table
struct SweepTable {
    texture: wgpu::Texture,
    view: wgpu::TextureView,
}

/// A pooled resource: its size `(width, height)` and its index in the pool's list for that
/// size.
type Slot = ((u32, u32), usize);

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
    let (mut tgt, mut data) = (0u64, 0u64);
    for &j in gpu_jobs {
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
            .map(|sw| (sw.words.len() as u64 * 8).next_multiple_of(limits.storage_align))
            .sum();
        let d = p.out.vertices.len() as u64 * VERTEX_SIZE
            + p.out.data.len() as u64 * 16
            + p.chunks.len() as u64 * limits.storage_align
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
    /// Each reprojection's summed-area table.
    tables: Vec<Slot>,
}

/// A wave's layout: its planes, in order, and the bytes each shared buffer must hold.
struct WaveLayout {
    planes: Vec<PlaneLayout>,
    vertex_bytes: u64,
    data_bytes: u64,
    window_bytes: u64,
    uniform_bytes: u64,
}

impl WaveLayout {
    /// Places the planes `todo` (indexes of `jobs` and `prepared`) one after the other: their
    /// vertices, their chunks' data and their reprojections' windows (each range aligned to
    /// `storage_align`), their uniforms [`UNIFORM_STRIDE`] apart, and the `k`-th plane of a
    /// size (the `k`-th table of a source size) in the pool's `k`-th target (table) of that
    /// size.
    fn new(todo: &[usize], jobs: &[PlaneJob], prepared: &[Prepared], storage_align: u64) -> Self {
        let (mut vertex_bytes, mut data_bytes, mut window_bytes) = (0u64, 0u64, 0u64);
        let mut targets_taken: HashMap<(u32, u32), usize> = HashMap::new();
        let mut tables_taken: HashMap<(u32, u32), usize> = HashMap::new();
        let take = |taken: &mut HashMap<(u32, u32), usize>, size: (u32, u32)| {
            let k = taken.entry(size).or_default();
            *k += 1;
            (size, *k - 1)
        };
        let mut planes = Vec::with_capacity(todo.len());
        for (w, &j) in todo.iter().enumerate() {
            let p = &prepared[j];
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
            planes.push(PlaneLayout {
                job: j,
                first_vertex,
                chunk_offsets,
                window_offsets,
                uniform_offset: w as u64 * UNIFORM_STRIDE,
                target: take(&mut targets_taken, (f.width, f.height)),
                tables: p
                    .sweeps
                    .iter()
                    .map(|sw| take(&mut tables_taken, sw.source_size))
                    .collect(),
            });
        }
        WaveLayout {
            planes,
            vertex_bytes,
            data_bytes,
            window_bytes,
            uniform_bytes: todo.len() as u64 * UNIFORM_STRIDE,
        }
    }

    /// Adds the wave's counters to `stats`: one submission, per plane one pass, its draws,
    /// occluders, triangles and edges, and the bytes uploaded and read back.
    fn count(&self, jobs: &[PlaneJob], prepared: &[Prepared], stats: &mut RenderStats) {
        stats.submissions += 1;
        stats.passes += self.planes.len();
        stats.bytes_uploaded += self.vertex_bytes + self.uniform_bytes;
        for plane in &self.planes {
            let p = &prepared[plane.job];
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
            let f = &jobs[plane.job].frame;
            stats.bytes_read_back += (f.width as u64 * 4).next_multiple_of(256) * f.height as u64;
        }
    }
}

/// The wave's shared buffers, once allocated.
struct WaveBuffers<'a> {
    vertices: &'a wgpu::Buffer,
    data: &'a wgpu::Buffer,
    uniforms: &'a wgpu::Buffer,
    /// Absent until some wave reprojects.
    windows: Option<&'a wgpu::Buffer>,
}

impl<'a> WaveBuffers<'a> {
    /// The pool's buffers, after [`GpuBackend::allocate`].
    fn of(pool: &'a Pool) -> Self {
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
    pub(super) fn render_wave(
        &self,
        pool: &mut Pool,
        jobs: &[PlaneJob],
        prepared: &[Prepared],
        todo: &[usize],
        out: &mut [Option<DepthMap>],
        stats: &mut RenderStats,
    ) -> Result<(), BackendError> {
        let scope = ErrorScopes::push(&self.device);
        let layout = WaveLayout::new(todo, jobs, prepared, self.limits.storage_align);
        self.allocate(pool, &layout)?;
        let pool = &*pool;
        let buffers = WaveBuffers::of(pool);
        self.upload(pool, &buffers, &layout, jobs, prepared);
        layout.count(jobs, prepared, stats);
        let timestamps = self.timestamp_period.map(|period| Timestamps {
            sets: &pool.timestamps[..timestamp_sets(layout.planes.len())],
            passes: layout.planes.len(),
            period,
        });
        let commands = self.encode(pool, &buffers, &layout, prepared, timestamps.as_ref());
        let (submission, mapped) = self.submit(pool, &layout, commands, timestamps.as_ref());
        scope.check()?;
        let waited = layout.planes.len() + timestamps.as_ref().map_or(0, |t| t.sets.len());
        self.wait(submission, mapped, waited)?;
        self.check_failure()?;
        if let Some(t) = &timestamps {
            stats.pass_time += t.read()?;
            stats.timed_passes += layout.planes.len();
        }
        read_back(pool, &layout, prepared, out)
    }

    /// Allocation step: grows the shared buffers to the layout's sizes and adds to the pools
    /// the targets and tables it places beyond their ends.
    ///
    /// # Errors
    /// [`BackendError::BufferTooLarge`] when a buffer would exceed the device's largest.
    fn allocate(&self, pool: &mut Pool, layout: &WaveLayout) -> Result<(), BackendError> {
        if self.timestamp_period.is_some() {
            while pool.timestamps.len() < timestamp_sets(layout.planes.len()) {
                pool.timestamps.push(TimestampSet::new(&self.device));
            }
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
        for plane in &layout.planes {
            let (size, k) = plane.target;
            let list = pool.targets.entry(size).or_default();
            if list.len() <= k {
                list.push(self.new_target(size));
            }
            for &(size, k) in &plane.tables {
                let list = pool.tables.entry(size).or_default();
                if list.len() <= k {
                    list.push(self.new_sweep_table(size));
                }
            }
        }
        Ok(())
    }

    /// Upload step: every plane's vertices, chunks of records and edges and reprojection
    /// windows at their offsets, the planes' uniforms (`2 / width`, `2 / height`: pixel to
    /// NDC scale), then the reprojections' summed-area tables.
    fn upload(
        &self,
        pool: &Pool,
        buffers: &WaveBuffers,
        layout: &WaveLayout,
        jobs: &[PlaneJob],
        prepared: &[Prepared],
    ) {
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
        for plane in &layout.planes {
            for (sw, &(size, k)) in prepared[plane.job].sweeps.iter().zip(&plane.tables) {
                let (width, height) = size;
                self.queue.write_texture(
                    wgpu::TexelCopyTextureInfo {
                        texture: &pool.tables[&size][k].texture,
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
            }
        }
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
        for (w, plane) in layout.planes.iter().enumerate() {
            let writes = timestamps.map(|t| t.writes(w));
            self.encode_plane(
                &mut encoder,
                pool,
                buffers,
                plane,
                &prepared[plane.job],
                writes,
            );
        }
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
        plane: &PlaneLayout,
        p: &Prepared,
        timestamp_writes: Option<wgpu::RenderPassTimestampWrites>,
    ) {
        let (size, k) = plane.target;
        let target = &pool.targets[&size][k];
        let chunk_groups = self.chunk_bind_groups(buffers, plane, p);
        let reproject_groups = self.reprojection_bind_groups(pool, buffers, plane, p);
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
                        wgpu::BindGroupEntry {
                            binding: 0,
                            resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                                buffer: buffers.uniforms,
                                offset: plane.uniform_offset,
                                size: NonZeroU64::new(16),
                            }),
                        },
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

    /// The bind groups of a plane's reprojection draws, one per reprojection: its windows and
    /// its summed-area table.
    fn reprojection_bind_groups(
        &self,
        pool: &Pool,
        buffers: &WaveBuffers,
        plane: &PlaneLayout,
        p: &Prepared,
    ) -> Vec<wgpu::BindGroup> {
        p.sweeps
            .iter()
            .zip(&plane.tables)
            .zip(&plane.window_offsets)
            .map(|((sw, &(size, k)), &off)| {
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
                            resource: wgpu::BindingResource::TextureView(
                                &pool.tables[&size][k].view,
                            ),
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
        let submission = self.queue.submit([commands]);
        let (tx, rx) = mpsc::channel();
        if let Some(t) = timestamps {
            // After the planes' mappings in the count the wait expects.
            for (k, set) in t.sets.iter().enumerate() {
                let tx = tx.clone();
                let w = layout.planes.len() + k;
                set.read_back
                    .map_async(wgpu::MapMode::Read, ..t.bytes(k), move |r| {
                        let _ = tx.send((w, r));
                    });
            }
        }
        for (w, plane) in layout.planes.iter().enumerate() {
            let tx = tx.clone();
            let (size, k) = plane.target;
            pool.targets[&size][k]
                .staging
                .map_async(wgpu::MapMode::Read, .., move |r| {
                    let _ = tx.send((w, r));
                });
        }
        (submission, rx)
    }

    /// Waiting step: polls the device in slices of [`POLL_SLICE`] until all `planes`
    /// read-back buffers are mapped, checking for a lost device between slices.
    ///
    /// # Errors
    /// As [`Self::poll_until`].
    fn wait(
        &self,
        submission: wgpu::SubmissionIndex,
        mapped: Mapped,
        planes: usize,
    ) -> Result<(), BackendError> {
        let mut done = vec![false; planes];
        let mut remaining = planes;
        self.poll_until(&submission, &format!("{planes} planes"), || {
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

    /// Polls the device in slices of [`POLL_SLICE`] until `done` says the work of
    /// `submission` (its read-backs mapped) is over, checking for a lost device between
    /// slices. `work` names the work in a timeout's message.
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
            match self.device.poll(wgpu::PollType::Wait {
                submission_index: Some(submission.clone()),
                timeout: Some(POLL_SLICE),
            }) {
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
            if start.elapsed() > DEADLINE {
                return Err(BackendError::Timeout {
                    work: work.to_string(),
                    deadline: DEADLINE,
                });
            }
        }
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

    /// A summed-area table texture (`R32Uint`) for a source of `size`.
    fn new_sweep_table(&self, size: (u32, u32)) -> SweepTable {
        let (texture, view) = self.map_texture(
            "reprojection table",
            size,
            wgpu::TextureFormat::R32Uint,
            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        );
        SweepTable { texture, view }
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
                label: Some("render pass timestamps"),
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

    /// The start and end timestamps of pass `w`.
    fn writes(&self, w: usize) -> wgpu::RenderPassTimestampWrites<'_> {
        let (k, i) = ((2 * w) / TIMESTAMPS_PER_SET, (2 * w) % TIMESTAMPS_PER_SET);
        wgpu::RenderPassTimestampWrites {
            query_set: &self.sets[k].set,
            beginning_of_pass_write_index: Some(i as u32),
            end_of_pass_write_index: Some(i as u32 + 1),
        }
    }

    /// Resolves the wave's timestamps and copies them to the mappable buffers.
    fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        for (k, s) in self.sets.iter().enumerate() {
            encoder.resolve_query_set(&s.set, 0..self.queries(k), &s.resolved, 0);
            encoder.copy_buffer_to_buffer(&s.resolved, 0, &s.read_back, 0, self.bytes(k));
        }
    }

    /// The summed GPU time of the wave's passes (mapped buffers), unmapping them.
    ///
    /// # Errors
    /// [`BackendError::ReadBack`] when a mapped range cannot be read.
    fn read(&self) -> Result<Duration, BackendError> {
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
        let sum: u64 = ticks
            .chunks_exact(2)
            .map(|p| p[1].saturating_sub(p[0]))
            .sum();
        Ok(Duration::from_nanos(
            (sum as f64 * self.period).round() as u64
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
    out: &mut [Option<DepthMap>],
) -> Result<(), BackendError> {
    for plane in &layout.planes {
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
        out[plane.job] = Some(map);
    }
    Ok(())
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
}
