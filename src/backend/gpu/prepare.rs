//! The CPU side of a `render` call, per job and outside the backend's lock: every occluder's
//! record, edges and geometry ([`setup`]) in draw chunks that fit one storage binding — or,
//! with [`GpuProjection::Counting`](super::GpuProjection::Counting), only the points and
//! Depth of the occluders whose views the GPU computes ([`Counted`]) — the slices as a mask,
//! and each reprojection's windows and summed-area table.

use super::setup::{self, Output, PlaneSetup, Scratch, Vertex};
use super::tables::{Cached, SweepTable, TableCache, UmbraBox};
use crate::backend::{BackendError, coverage};
use crate::plane::{DepthMap, PlaneJob, Reprojection, Window, depth_up};
use rayon::prelude::*;
use std::sync::Arc;

/// Occluders per rayon task of the setup.
const SETUP_TASK: usize = 1024;

/// A job's CPU-side preparation.
pub(super) struct Prepared {
    /// Records, edges and geometry; vertices' record indices are relative to their chunk.
    pub out: Output,
    /// Occluders set up (those the quick rejects kept).
    pub occluders: usize,
    /// Draw chunks: vertex range and data range.
    pub chunks: Vec<Chunk>,
    /// The slices as a map (`0` inside, `+inf` elsewhere), merged on read-back.
    pub mask: Option<DepthMap>,
    /// The job's reprojections that can set a pixel, in the job's order.
    pub sweeps: Vec<SweepSetup>,
    /// With [`GpuProjection::Counting`](super::GpuProjection::Counting): the occluders whose
    /// views the GPU computes (`shaders/views.wgsl`); empty otherwise.
    pub counted: Counted,
}

/// Occluders of a job handed to the GPU as they are (`shaders/views.wgsl`): points and Depth
/// only, no CPU work beyond the Depth.
#[derive(Clone, Debug, Default)]
pub(super) struct Counted {
    /// Their points, 3 `f64` each.
    pub points: Vec<f64>,
    /// Per occluder `[first point, point count, Depth bits, first record word]`, relative to
    /// this job; the wave rebases the point and the record word and adds the plane's index
    /// (`count | plane << 8`).
    pub occ: Vec<[u32; 4]>,
    /// Record words reserved: `2 + 8·n` per occluder of `n` points (a view's hull has at most
    /// `n` edges).
    pub record_words: usize,
    /// Per occluder, the scene part it is unchanged ([`crate::plane::OccluderSet::parts`]),
    /// or [`crate::plane::NO_PART`]: with the parts on the device its points need not go up.
    pub parts: Vec<u32>,
}

impl Counted {
    /// Number of occluders.
    pub fn len(&self) -> usize {
        self.occ.len()
    }

    /// True when there are none.
    pub fn is_empty(&self) -> bool {
        self.occ.is_empty()
    }

    /// Where occluder `i`'s points lie in the resident table `parts` when the job's
    /// occluders name it (`table`, [`crate::plane::OccluderSet::table`]) and the occluder is
    /// a part of it unchanged; `None`: its points go up.
    pub fn resident_span(
        &self,
        parts: Option<&super::resident::ResidentParts>,
        table: Option<u64>,
        i: usize,
    ) -> Option<(u32, u32)> {
        let part = self
            .parts
            .get(i)
            .copied()
            .filter(|&p| p != crate::plane::NO_PART);
        parts?.span(table, part, self.occ[i][1] as usize)
    }
}

/// Most points of an occluder whose views the GPU computes (`MAXP` in `shaders/views.wgsl`).
pub(super) const COUNTED_MAX_POINTS: usize = 8;

/// Where a reprojection's summed-area table comes from.
#[derive(Clone, Debug)]
pub(super) enum TableSource {
    /// Built by this call: the source's summed-area table of pixels outside the umbra,
    /// row-major (entry `(x, y)` counts the source pixels in `[0, x] × [0, y]` whose Depth is
    /// not `≤ 0`), to upload into a texture and cache for `source` with its `umbra` box.
    Upload {
        table: Vec<u32>,
        source: Arc<DepthMap>,
        umbra: [u32; 4],
    },
    /// On the device already, from an earlier reprojection of the same source
    /// ([`TableCache`]).
    Cached(Arc<SweepTable>),
}

/// One reprojection of a job, prepared for the GPU (see [`sweep_setup`]).
#[derive(Clone, Debug)]
pub(super) struct SweepSetup {
    /// The storage data: `[depth bits, target width]`, `[+inf bits, source width]`,
    /// `[source height, 0]`, then the column windows, then the row windows
    /// (`shaders/reproject.wgsl`).
    pub words: Vec<[u32; 2]>,
    /// The source's (and the table's) `(width, height)`.
    pub source_size: (u32, u32),
    /// Its summed-area table: built now, or cached on the device.
    pub table: TableSource,
    /// The draw's scissor rectangle `[x, y, width, height]`: the bounding box of the target
    /// pixels the reprojection may set.
    pub scissor: [u32; 4],
}

/// One draw of a plane's occluders: its vertices (relative to the plane's first) and its
/// words of the plane's data, which fit one storage binding.
#[derive(Clone, Debug)]
pub(super) struct Chunk {
    pub vertices: std::ops::Range<u32>,
    pub data: std::ops::Range<usize>,
}

/// CPU setup of one job: records, edges and geometry of every occluder ([`setup_occluders`]),
/// split into draw chunks whose data fits `max_chunk_words` ([`split_chunks`]) — with
/// `counting`, only of those the views pass does not take ([`count_occluders`]) — the slice
/// mask, and the reprojections that can set a pixel, their tables taken from `tables` where
/// an earlier reprojection of the same source left them.
///
/// # Errors
/// [`BackendError::OccluderTooLarge`] when one occluder's data exceed `max_chunk_words`.
pub(super) fn prepare(
    job: &PlaneJob,
    max_chunk_words: usize,
    counting: bool,
    tables: &TableCache,
) -> Result<Prepared, BackendError> {
    let counted = if counting {
        count_occluders(job, max_chunk_words)
    } else {
        None
    };
    let (mut out, occluders) = setup_occluders(job, counted.as_ref().map(|c| c.1.as_slice()));
    let chunks = split_chunks(&mut out, max_chunk_words)?;
    Ok(Prepared {
        out,
        occluders,
        chunks,
        mask: slice_mask(job),
        sweeps: job
            .reproject
            .par_iter()
            .filter_map(|r| sweep_setup(r, tables))
            .collect(),
        counted: counted.map(|c| c.0).unwrap_or_default(),
    })
}

/// The job's occluders of at most [`COUNTED_MAX_POINTS`] points, handed to the GPU as they
/// are, and the indexes of the others (set up on the CPU). `None` (all on the CPU) when their
/// records would not fit one storage binding of `max_chunk_words`.
fn count_occluders(job: &PlaneJob, max_chunk_words: usize) -> Option<(Counted, Vec<usize>)> {
    let frame = &job.frame;
    let mut c = Counted::default();
    let mut rest = Vec::new();
    for k in 0..job.occluders.len() {
        let pts = job.occluders.get(k);
        if pts.len() > COUNTED_MAX_POINTS || pts.len() < 3 {
            rest.push(k);
            continue;
        }
        let depth = frame.far_depth(pts);
        c.occ.push([
            (c.points.len() / 3) as u32,
            pts.len() as u32,
            depth_up(depth).to_bits(),
            c.record_words as u32,
        ]);
        c.points.extend(pts.iter().flat_map(|p| p.to_array()));
        c.record_words += 2 + 8 * pts.len();
        c.parts.push(
            job.occluders
                .parts
                .get(k)
                .copied()
                .unwrap_or(crate::plane::NO_PART),
        );
    }
    (c.record_words + c.occ.len() <= max_chunk_words).then_some((c, rest))
}

/// The job's occluders `which` (all when `None`) set up ([`setup::occluder`]) in parallel
/// tasks of [`SETUP_TASK`], concatenated in order (record indices rebased); with the number
/// set up.
fn setup_occluders(job: &PlaneJob, which: Option<&[usize]>) -> (Output, usize) {
    let frame = &job.frame;
    let ps = PlaneSetup::new(frame);
    let n = which.map_or(job.occluders.len(), <[usize]>::len);
    let parts: Vec<(Output, usize)> = (0..n.div_ceil(SETUP_TASK))
        .into_par_iter()
        .map(|t| {
            let mut scratch = Scratch::default();
            let mut out = Output::default();
            let mut count = 0;
            for i in t * SETUP_TASK..((t + 1) * SETUP_TASK).min(n) {
                let pts = job.occluders.get(which.map_or(i, |w| w[i]));
                let depth = frame.far_depth(pts);
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
    (out, occluders)
}

/// Splits `out` into chunks whose data fits one storage binding of `max_chunk_words`, and
/// rebases the vertices' record indices onto their chunk's data.
///
/// # Errors
/// [`BackendError::OccluderTooLarge`] when one occluder's data exceed `max_chunk_words`.
fn split_chunks(out: &mut Output, max_chunk_words: usize) -> Result<Vec<Chunk>, BackendError> {
    let mut chunks = Vec::new();
    let (mut first, mut base, mut current) = (0usize, 0usize, u32::MAX);
    for k in 0..out.vertices.len() {
        let rec = out.vertices[k].record;
        if rec != current {
            current = rec;
            let end = rec as usize + 1 + out.data[rec as usize][2] as usize;
            if end - rec as usize > max_chunk_words {
                return Err(BackendError::OccluderTooLarge {
                    edges: end - rec as usize - 1,
                });
            }
            if end - base > max_chunk_words {
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
    Ok(chunks)
}

/// A reprojection prepared for the GPU, or `None` when it cannot set a pixel.
///
/// The summed-area table of the source's pixels outside the umbra ([`umbra_table`], the same
/// `d <= 0` test as [`Reprojection::mask`]) and its umbra's bounding box are built once per
/// source and kept on the device ([`TableCache`]); later reprojections of the same source
/// take them from there. A target pixel `(i, j)` can
/// only be set when its windows are valid and `cols[i] × rows[j]` lies inside the bounding box
/// of the umbra (every column and row of the box then holds an umbra pixel); the draw is
/// scissored to the bounding box of those pixels, and outside it a draw would write `+inf`
/// anyway. No umbra, or no such pixel: `None`.
fn sweep_setup(r: &Reprojection, cache: &TableCache) -> Option<SweepSetup> {
    let (sw, sh) = (r.source.width, r.source.height);
    // Windows first: O(width + height), and a reprojection without any skips the table.
    let any_valid = |w: &[Window], len: u32| w.iter().any(|&[a, b]| a <= b && b < len);
    if !any_valid(&r.cols, sw) || !any_valid(&r.rows, sh) {
        return None;
    }
    let (table, [x0, x1, y0, y1]) = match cache.get(&r.source) {
        Some(c) => (TableSource::Cached(c.table?), c.umbra?),
        None => {
            let (table, umbra) = umbra_table(&r.source);
            let Some(b) = umbra else {
                cache.insert(
                    &r.source,
                    Cached {
                        table: None,
                        umbra: None,
                    },
                );
                return None;
            };
            (
                TableSource::Upload {
                    table,
                    source: r.source.clone(),
                    umbra: b,
                },
                b,
            )
        }
    };
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

/// The summed-area table of `source`'s pixels outside the umbra, row-major (entry `(x, y)`
/// counts the pixels in `[0, x] × [0, y]` whose Depth is not `≤ 0`), built in one pass, and
/// the umbra's bounding box `[x0, x1, y0, y1]` (inclusive; `None` without umbra).
fn umbra_table(source: &DepthMap) -> (Vec<u32>, UmbraBox) {
    let (sw, sh) = (source.width, source.height);
    let (n, m) = (sw as usize, sh as usize);
    let mut table = vec![0u32; n * m];
    for (y, src) in source.depth.chunks_exact(n).enumerate() {
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
        return (table, None);
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
    let umbra = bounds(&column, n, sh)
        .zip(bounds(&row, m, sw))
        .map(|((x0, x1), (y0, y1))| [x0, x1, y0, y1]);
    (table, umbra)
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
pub(super) fn merge_mask(map: &mut DepthMap, mask: &DepthMap) {
    for (d, m) in map.depth.iter_mut().zip(&mask.depth) {
        if *m < *d {
            *d = *m;
        }
    }
}
