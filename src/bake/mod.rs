//! Baking: the settings ([`BakeSettings`]), the bake of every cell ([`bake`]) and its PVS
//! document ([`to_document`]). A scene is prepared once ([`Prepared`], `prepare.rs`); every
//! cell — or every sub-cell of it with `subcell` — then runs the pipeline of cullers
//! (`pipeline.rs`, [`Culler`]): today extended projections on separate planes or the occlusion
//! sweep (`planes.rs`), then the shrunk-occluder sampler (`sampling.rs`). With
//! `max_pvs_triangles` a cell over budget is halved and its halves baked with its hidden set
//! ([`CellResult::children`], `prepare.rs`). Cells run in parallel
//! (rayon); [`bake_cells`] bakes a subset of them (a shard, the rest of a resumed bake) and
//! reports each finished cell (to the journal, `journal.rs`); shards are merged in `shard.rs`.

mod checkpoint;
mod journal;
mod pipeline;
mod planes;
mod prepare;
mod rsf;
mod sampling;
mod shard;

pub use checkpoint::{CHECKPOINT_FORMAT, CHECKPOINT_VERSION, SamplerCheckpoints};
pub use journal::{
    JOURNAL_MAGIC, JOURNAL_VERSION, Journal, JournalError, inputs_hash, journal_path,
};
pub use pipeline::{
    CULLER_NAMES, CullState, Culler, CullerStats, CullerWork, EXTENDED_PROJECTIONS, NoPlanes,
    OCCLUSION_SWEEP, PlaneSink, RAY_SPACE_FACTORIZATION, SHRUNK_SAMPLING, cullers,
};
pub use planes::{PlaneCuller, SWEEP_TEST_REACH};
pub use prepare::{
    MIN_CELL_FRACTION, MIN_SPLIT_GAIN, PIECE_LEVELS, PIECE_MIN_TRIANGLES, Prepared,
    SAMPLING_AUTO_NOTE, SMALL_OCCLUDER_CELLS, SMALL_OCCLUDER_SHARE, choose_sweep, halve,
    split_cell,
};
pub use rsf::{RSF_AUTO_UPRIGHT_SHARE, RsfCuller, UPRIGHT_SLOPE, choose_rsf};
pub use sampling::{GPU_SAMPLERS_BUDGET, SamplerData, SamplingCuller};
pub use shard::{MergeError, SHARD_FORMAT, SHARD_VERSION, ShardFile, ShardSpec, merge};

use crate::backend::{BackendError, RasterBackend};
use crate::geom::Aabb;
use crate::hdm::Hdm;
use crate::plane::{DepthMap, PlaneJob};
use crate::pvs::{
    FORMAT, PvsCell, PvsCullerSummary, PvsDocument, PvsObject, PvsSettings, PvsSummary, VERSION,
};
use crate::scene::Scene;
use rayon::prelude::*;
use std::time::Instant;

pub use crate::settings::{BakeSettings, SettingsError, SweepChoice};

/// Bake failures.
#[derive(Debug, thiserror::Error)]
pub enum BakeError {
    /// A setting out of its range (or an `--occluders` pattern that is not a glob).
    #[error(transparent)]
    Settings(#[from] SettingsError),
    /// The backend failed (no adapter, device lost…).
    #[error(transparent)]
    Backend(#[from] BackendError),
    /// A finished cell could not be written to the journal.
    #[error(transparent)]
    Journal(#[from] JournalError),
    /// The sampler's checkpoint inside a cell could not be written (`--sampling-checkpoint`).
    #[error("the sampler's checkpoint: {0}")]
    Checkpoint(crate::util::WriteError),
    /// The occluders have more corners than the occluder tables' `u32` indices reach.
    #[error(
        "the occluders have {0} corners, more than the 4,294,967,295 the occluder tables can \
         index: choose fewer occluders with --occluders PATTERN, or bake the scene in parts"
    )]
    TooManyOccluderCorners(u64),
    /// The sampler stopped right after a checkpoint, as a test asked
    /// ([`SamplerCheckpoints::stop_after_writes`]).
    #[error("the sampler stopped after its checkpoint, as asked")]
    Interrupted,
}

/// One cell's outcome.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CellResult {
    /// Potentially visible object ids, ascending.
    pub visible: Vec<u32>,
    /// Wall time spent baking this cell, in milliseconds.
    pub ms: f64,
    /// Planes rasterised and occluder Projections sent to the backend.
    pub planes: usize,
    /// Occluder projections sent to the backend, over all planes of the cell.
    pub occluders_projected: usize,
    /// Per culler of the pipeline ([`BakeResult::cullers`]), its account for this cell.
    pub cullers: Vec<CullerStats>,
    /// With adaptive subdivision (`max_pvs_triangles`): the two halves this cell was split
    /// into, each baked testing only this cell's PVS; empty when it was not split.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub children: Vec<ChildCell>,
}

/// One half of a subdivided cell: its box and its own result (which may be subdivided again).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ChildCell {
    /// Lower corner.
    pub min: [f32; 3],
    /// Upper corner.
    pub max: [f32; 3],
    /// Its bake.
    pub result: CellResult,
}

impl CellResult {
    /// This cell and its subdivision, depth first (a cell before its halves, the lower half
    /// first), each with the index in that order of the cell it is a half of: the order of
    /// the PVS document's cells after the cells given to the bake.
    pub fn flatten(&self, bounds: Aabb) -> Vec<(Aabb, Option<usize>, &CellResult)> {
        fn walk<'r>(
            r: &'r CellResult,
            b: Aabb,
            parent: Option<usize>,
            out: &mut Vec<(Aabb, Option<usize>, &'r CellResult)>,
        ) {
            let me = out.len();
            out.push((b, parent, r));
            for c in &r.children {
                walk(
                    &c.result,
                    Aabb::new(c.min.into(), c.max.into()),
                    Some(me),
                    out,
                );
            }
        }
        let mut out = Vec::new();
        walk(self, bounds, None, &mut out);
        out
    }

    /// The cells of this cell's subdivision that were not split further (itself when it was
    /// not subdivided).
    pub fn leaves(&self) -> Vec<&CellResult> {
        let mut out = Vec::new();
        let mut stack = vec![self];
        while let Some(c) = stack.pop() {
            if c.children.is_empty() {
                out.push(c);
            } else {
                stack.extend(c.children.iter().rev().map(|h| &h.result));
            }
        }
        out
    }
}

/// A whole bake's outcome (a shard file keeps it whole: `shard.rs`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BakeResult {
    /// Per cell, in the order of the cells given to the bake.
    pub cells: Vec<CellResult>,
    /// The backend's name ([`RasterBackend::name`], e.g. `cpu` or `gpu`).
    pub backend: String,
    /// The GPU adapter's description, `None` for the CPU backend.
    pub adapter: Option<String>,
    /// Triangles used as occluders (opaque, selected, not degenerate).
    pub occluder_triangles: usize,
    /// What the alpha-tested cards gave as occluders (`None` without cards or with their
    /// coverage off).
    #[serde(default)]
    pub cards: Option<crate::project::occluders::CardStats>,
    /// Zero-area triangles skipped.
    pub degenerate_triangles: usize,
    /// Wall time of the whole bake (preparation included), in seconds.
    pub seconds: f64,
    /// Whether the bake swept, and why (for the summary).
    pub sweep: bool,
    /// Why the bake swept or not, one human-readable line.
    pub sweep_reason: String,
    /// Whether cells ran ray space factorization first.
    #[serde(default)]
    pub rsf: bool,
    /// Why ray space factorization ran or not, one human-readable line.
    #[serde(default)]
    pub rsf_reason: String,
    /// Whether cells ran the shrunk-occluder sampler.
    pub sampling: bool,
    /// Why the sampler ran or not, and its finest ε.
    pub sampling_reason: String,
    /// With a GPU backend and the sampler on: where it rendered, `on the GPU` or `on the CPU:`
    /// and why ([`crate::backend::gpu::sampler::GpuSamplerScene::refusal`]); otherwise `None`.
    #[serde(default)]
    pub sampling_device: Option<String>,
    /// What the cullers shared over the whole bake, one line each ([`Culler::note`]: the
    /// sampler's GPU memory and waits). Not written: it depends on the threads.
    #[serde(skip)]
    pub notes: Vec<String>,
    /// The names of the cullers every cell ran, in order (read back against
    /// [`CULLER_NAMES`]).
    #[serde(deserialize_with = "pipeline::culler_names")]
    pub cullers: Vec<&'static str>,
}

/// Ray space factorization's charts of the cells `which` of `cells` (for `--dump-exr`): each
/// cell's four charts as its traversal leaves them, or `None` when the bake would not run it
/// (the settings' `rsf` and the automatic rule).
///
/// # Errors
/// Invalid settings, or an index out of range.
pub fn rsf_charts(
    scene: &Scene,
    cells: &[Aabb],
    which: &[usize],
    settings: &BakeSettings,
) -> Result<Option<Vec<(usize, crate::rsf::RayCharts)>>, BakeError> {
    if let Some(&bad) = which.iter().find(|&&i| i >= cells.len()) {
        return Err(BakeError::Settings(SettingsError {
            option: "dump-cells",
            value: bad.to_string(),
            expected: format!("cell indices below {}", cells.len()),
        }));
    }
    let prepared = Prepared::new(scene, settings, cells)?;
    if !prepared.rsf {
        return Ok(None);
    }
    Ok(Some(
        which
            .par_iter()
            .map(|&ci| (ci, rsf::cell_charts(&prepared, &cells[ci])))
            .collect(),
    ))
}

/// Bakes every cell. `progress` is called after each cell with the number done.
///
/// # Errors
/// Invalid settings, or the backend's failure (no partial result).
pub fn bake(
    scene: &Scene,
    cells: &[Aabb],
    settings: &BakeSettings,
    backend: &dyn RasterBackend,
    progress: Option<&(dyn Fn(usize) + Sync)>,
) -> Result<BakeResult, BakeError> {
    bake_observed(scene, cells, settings, backend, progress, None)
}

/// Observer of every rendered plane: `(cell index, plane index within the cell, job, Depth
/// Map, Hierarchical Depth Map)`.
pub type PlaneObserver<'a> = &'a (dyn Fn(usize, usize, &PlaneJob, &DepthMap, &Hdm) + Sync);

/// [`bake`], handing every rendered plane to `observe` (for dumps and reports).
///
/// # Errors
/// Invalid settings, or the backend's failure (no partial result).
pub fn bake_observed(
    scene: &Scene,
    cells: &[Aabb],
    settings: &BakeSettings,
    backend: &dyn RasterBackend,
    progress: Option<&(dyn Fn(usize) + Sync)>,
    observe: Option<PlaneObserver>,
) -> Result<BakeResult, BakeError> {
    let all: Vec<usize> = (0..cells.len()).collect();
    bake_cells(
        scene,
        cells,
        &all,
        settings,
        backend,
        BakeHooks {
            progress,
            observe,
            on_cell: None,
            sampler_progress: None,
            sampler_checkpoints: None,
        },
    )
}

/// Observer of every finished cell: `(cell index, result)`; an error stops the bake.
pub type CellObserver<'a> = &'a (dyn Fn(usize, &CellResult) -> Result<(), JournalError> + Sync);

/// The shrunk-occluder sampler's work so far, for progress inside cells that take minutes
/// or hours ([`BakeHooks::sampler_progress`]), summed over the cells in flight.
#[derive(Debug, Default)]
pub struct SamplerProgress {
    /// Sample points rendered (or replayed from a checkpoint).
    pub points: std::sync::atomic::AtomicU64,
    /// Face rectangles of the levels begun so far (a level's are added when it starts: with
    /// `--sampling-levels 0` the cell's whole count at once).
    pub rects_begun: std::sync::atomic::AtomicU64,
    /// Face rectangles finished: sampled, replayed from a checkpoint, left unsampled after a
    /// level's probe, or given up.
    pub rects_done: std::sync::atomic::AtomicU64,
}

/// How fast the sampler gets through the face rectangles of the levels begun, for progress
/// lines: measured from the moment the count begun last changed (a level started), so that
/// each level is timed on its own rectangles, whose cost differs by orders of magnitude
/// between levels. The pace is that of the sample points, which move one by one, where
/// rectangles are counted done a whole chunk at a time; each point since the level began
/// stands for one of its rectangles.
#[derive(Clone, Copy, Debug, Default)]
pub struct RectPace {
    /// When the rectangles begun last changed, and the points and rectangles done then
    /// (`None` before the first update).
    since: Option<(std::time::Instant, u64, u64)>,
    /// The rectangles begun then.
    begun: u64,
}

impl RectPace {
    /// The seconds at least between a level's start and an estimate: before, the pace of a
    /// handful of points says little.
    pub const MIN_SECONDS: f64 = 10.0;

    /// Notes the sample points rendered and the rectangles `(done, begun)` at `now`
    /// ([`SamplerProgress`]); returns about how long the rectangles begun but not yet done
    /// will take at the pace of the points since their level began, one point each (`None`:
    /// nothing to estimate yet). Rectangles that a level's probe leaves unsampled take no
    /// time, so such a level finishes sooner than the estimate says; points replayed from a
    /// checkpoint count too, so a resumed level looks faster than it is until they are past.
    pub fn update(
        &mut self,
        now: std::time::Instant,
        points: u64,
        (done, begun): (u64, u64),
    ) -> Option<std::time::Duration> {
        let Some((t0, p0, d0)) = self.since.filter(|_| begun == self.begun) else {
            self.since = Some((now, points, done));
            self.begun = begun;
            return None;
        };
        let seconds = (now - t0).as_secs_f64();
        let rendered = points.saturating_sub(p0);
        if rendered == 0 || seconds < Self::MIN_SECONDS {
            return None;
        }
        let left = begun.saturating_sub(done.max(d0 + rendered));
        (left > 0)
            .then(|| std::time::Duration::from_secs_f64(seconds / rendered as f64 * left as f64))
    }
}

/// What [`bake_cells`] reports while it works.
#[derive(Clone, Copy, Default)]
pub struct BakeHooks<'a> {
    /// Called after each cell with the number done.
    pub progress: Option<&'a (dyn Fn(usize) + Sync)>,
    /// Every rendered plane (dumps and reports).
    pub observe: Option<PlaneObserver<'a>>,
    /// Every finished cell, by its index in `cells`, from the worker that baked it (the
    /// journal); an error stops the bake.
    pub on_cell: Option<CellObserver<'a>>,
    /// The shrunk-occluder sampler counts its sample points and face rectangles here as it
    /// goes, so that a caller can show how far cells that take minutes or hours are.
    pub sampler_progress: Option<&'a SamplerProgress>,
    /// Where the sampler saves its progress inside each cell (`bake --resume` continues a
    /// cell from it); `None`: nowhere.
    pub sampler_checkpoints: Option<&'a SamplerCheckpoints>,
}

/// Bakes the cells `which` (indices into `cells`) of a bake of all `cells`: the per-scene
/// choices (the sweep's rule, the sampler's) are made for all of them, so that the cells of
/// a shard or of a resumed bake come out as they would in one bake. `result.cells` follows
/// `which`.
///
/// # Errors
/// Invalid settings, an index out of range, the backend's or `on_cell`'s failure (no partial
/// result).
pub fn bake_cells(
    scene: &Scene,
    cells: &[Aabb],
    which: &[usize],
    settings: &BakeSettings,
    backend: &dyn RasterBackend,
    hooks: BakeHooks,
) -> Result<BakeResult, BakeError> {
    let start = Instant::now();
    if let Some(&bad) = which.iter().find(|&&i| i >= cells.len()) {
        return Err(BakeError::Settings(SettingsError {
            option: "cells",
            value: bad.to_string(),
            expected: format!("cell indices below {}", cells.len()),
        }));
    }
    let mut prepared = Prepared::new(scene, settings, cells)?;
    if backend.tests_on_device() {
        prepared.occludee_table = backend.upload_occludee_boxes(&prepared.occludee_boxes())?;
    }
    // (Empty where the backend keeps no table: that only drops one kept before.)
    let spans: Vec<(u32, u32)> = if backend.keeps_occluder_parts() {
        (prepared.occluders.parts.iter())
            .map(|p| (p.start, p.end))
            .collect()
    } else {
        Vec::new()
    };
    prepared.occluder_table = backend.upload_occluder_parts(&prepared.occluders.points, &spans)?;
    prepared.sampler_progress = hooks.sampler_progress;
    prepared.checkpoints = hooks.sampler_checkpoints;
    let done = std::sync::atomic::AtomicUsize::new(0);
    let cells_out: Result<Vec<CellResult>, BakeError> = which
        .par_iter()
        .map(|&ci| {
            let c = &cells[ci];
            let r = match hooks.observe {
                None => prepared.cell(c, backend),
                Some(f) => {
                    let mut k = 0;
                    prepared.cell_observed(
                        c,
                        backend,
                        &mut |job: &PlaneJob, map: &DepthMap, hdm: &Hdm| {
                            f(ci, k, job, map, hdm);
                            k += 1;
                        },
                    )
                }
            }?;
            if let Some(f) = hooks.on_cell {
                f(ci, &r)?;
            }
            let k = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            if let Some(p) = hooks.progress {
                p(k);
            }
            Ok(r)
        })
        .collect();
    Ok(BakeResult {
        cells: cells_out?,
        backend: backend.name().to_string(),
        adapter: backend.adapter(),
        occluder_triangles: prepared.occluders.stats.triangles,
        cards: (prepared.occluders.cards.triangles > 0).then_some(prepared.occluders.cards),
        degenerate_triangles: scene.degenerate_triangles(),
        seconds: start.elapsed().as_secs_f64(),
        sweep: prepared.sweep,
        sweep_reason: prepared.sweep_reason.clone(),
        rsf: prepared.rsf,
        rsf_reason: prepared.rsf_reason.clone(),
        sampling: prepared.sampling,
        sampling_reason: prepared.sampling_reason.clone(),
        sampling_device: prepared.sampler_device(backend),
        notes: prepared.culler_notes(),
        cullers: prepared.culler_names(),
    })
}

impl BakeResult {
    /// Sets every timing to 0 (per-cell and per-culler milliseconds, the total seconds), so
    /// that the same inputs give byte-identical PVS files (`bake --reproducible`).
    pub fn clear_timings(&mut self) {
        self.seconds = 0.0;
        let mut stack: Vec<&mut CellResult> = self.cells.iter_mut().collect();
        while let Some(c) = stack.pop() {
            c.ms = 0.0;
            for s in &mut c.cullers {
                s.ms = 0.0;
                for l in &mut s.work.levels {
                    l.seconds = 0.0;
                }
            }
            stack.extend(c.children.iter_mut().map(|h| &mut h.result));
        }
    }
}

/// Bytes of peak memory per scene triangle a bake needs beyond the loaded scene, measured on
/// the paper-size forest (7.9 M triangles: 2.98 GB peak, 0.39 GB of it the scene).
pub const BAKE_BYTES_PER_TRIANGLE: u64 = 340;
/// More bytes per triangle with the shrunk-occluder sampler (its polygons, BVH and pieces).
pub const SAMPLER_BYTES_PER_TRIANGLE: u64 = 200;
/// More bytes per possible card polygon with the shrunk-occluder sampler (the polygon, its
/// box and BVH nodes in the sampler's occluders). Measured 341 on the dense beech forest
/// (`gen forest --preset coarse --tree-model …euro_beech… --trees 300 --area-per-tree 20`,
/// `--alpha-mips 4`: 8.9 M card polygons, peak 13.5 GB with the sampler against 8.6 GB
/// without, where the estimate without this term said 10.1 GB); rounded up.
pub const SAMPLER_BYTES_PER_CARD_POLYGON: u64 = 400;
/// Bytes per worker thread: Depth Maps, pyramids and scratch of one cell in flight.
pub const BAKE_BYTES_PER_THREAD: u64 = 96 << 20;

/// An estimate of a bake's peak memory in bytes (the loaded scene included), for refusing
/// a bake that cannot fit before it starts: the scene's arrays, [`BAKE_BYTES_PER_TRIANGLE`]
/// (plus [`SAMPLER_BYTES_PER_TRIANGLE`] with the sampler on), [`CARD_POLYGON_BYTES`] for each
/// polygon the alpha-tested cards may give (`alpha_card_polygons` per card triangle; plus
/// [`SAMPLER_BYTES_PER_CARD_POLYGON`] with the sampler on) and
/// [`BAKE_BYTES_PER_THREAD`] per thread, plus with the sampler one hemicube per thread at its
/// largest resolution (`SamplingSettings::hemicube_bytes`). It over-estimates the paper-size
/// forest by about 10 %.
pub fn estimate_memory(scene: &Scene, settings: &BakeSettings, threads: usize) -> u64 {
    let tris = scene.triangles.len() as u64;
    let loaded = scene.vertices.len() as u64 * 12 + tris * 13 + scene.objects.len() as u64 * 96;
    let sampling = settings.sampling == SweepChoice::On;
    let sampler = if sampling {
        SAMPLER_BYTES_PER_TRIANGLE
    } else {
        0
    };
    // Alpha-tested cards: up to `alpha_card_polygons` polygons per card triangle, plus what
    // the scene keeps per card (texture coordinates, vertex alpha, the ray caster's copy).
    let cards = scene.alpha.as_ref().map_or(0, |a| a.cards.len() as u64);
    let card_polygons = if settings.alpha_cards == crate::settings::AlphaCards::Coverage
        && !settings.alpha_occluders
    {
        let each = CARD_POLYGON_BYTES
            + if sampling {
                SAMPLER_BYTES_PER_CARD_POLYGON
            } else {
                0
            };
        cards * settings.alpha_card_polygons as u64 * each
    } else {
        0
    };
    // One hemicube per worker thread at the largest resolution the sampler may render.
    let hemicube = if sampling {
        crate::settings::SamplingSettings::hemicube_bytes(
            settings.sampling_settings.max_resolution(),
        )
    } else {
        0
    };
    loaded
        + tris * (BAKE_BYTES_PER_TRIANGLE + sampler)
        + cards * 2 * CARD_BYTES
        + card_polygons
        + threads as u64 * (BAKE_BYTES_PER_THREAD + hemicube)
}

/// Bytes per card polygon a bake may hold (points, part, its projections and sweep data):
/// measured 590 on a forest of 300 beeches with `--alpha-mips 4 --alpha-card-polygons 16`
/// (35.8 M polygons, peak 24.4 GB against 3.0 GB with the cards ignored).
pub const CARD_POLYGON_BYTES: u64 = 600;
/// Bytes per card triangle the scene keeps ([`crate::scene::alpha::CardTriangle`] and its
/// index).
const CARD_BYTES: u64 = 44;

/// Median of a list (0 for none).
pub fn median(values: &[f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

/// The PVS documents' object table: every object of the scene by id, with its name, triangle
/// count and bounds.
pub fn object_table(scene: &Scene) -> Vec<PvsObject> {
    scene
        .objects
        .iter()
        .enumerate()
        .map(|(i, o)| PvsObject {
            id: i as u32,
            name: o.name.clone(),
            triangles: o.triangles.len() as u32,
            min: o.bounds.min.to_array(),
            max: o.bounds.max.to_array(),
        })
        .collect()
}

/// Builds the JSON PVS document of a bake, with its summary.
pub fn to_document(
    scene: &Scene,
    cells: &[Aabb],
    result: &BakeResult,
    settings: &BakeSettings,
) -> PvsDocument {
    let mut doc = document(
        scene.source.display().to_string(),
        object_table(scene),
        scene.triangles.len(),
        cells,
        result,
        settings,
    );
    doc.split = scene
        .split
        .as_ref()
        .map(crate::scene::split::SplitMap::to_pvs);
    doc
}

/// [`to_document`] from the parts of a scene it uses: its path as recorded, its object table
/// and its triangle count (a merge of shards rebuilds the document from these).
pub fn document(
    source: String,
    objects: Vec<PvsObject>,
    triangles: usize,
    cells: &[Aabb],
    result: &BakeResult,
    settings: &BakeSettings,
) -> PvsDocument {
    let tri_count = |o: u32| objects[o as usize].triangles as usize;
    let total_tris = triangles.max(1);
    let n_obj = objects.len().max(1);
    // The cells given to the bake, then each one's subdivision depth first.
    let mut flat: Vec<(Aabb, Option<usize>, &CellResult)> = (cells.iter().copied())
        .zip(&result.cells)
        .map(|(b, c)| (b, None, c))
        .collect();
    for (i, (b, c)) in cells.iter().zip(&result.cells).enumerate() {
        let base = flat.len();
        for (bx, parent, r) in c.flatten(*b).into_iter().skip(1) {
            let parent = match parent {
                Some(0) | None => i,
                Some(k) => base + k - 1,
            };
            flat.push((bx, Some(parent), r));
        }
    }
    // Culling figures over the cells a run-time lookup ends in (not split further).
    let (mut obj_pct, mut tri_pct, mut leaves) = (0.0, 0.0, 0usize);
    for (_, _, c) in flat.iter().filter(|(_, _, c)| c.children.is_empty()) {
        obj_pct += 100.0 * (1.0 - c.visible.len() as f64 / n_obj as f64);
        let vis_tris: usize = c.visible.iter().map(|&o| tri_count(o)).sum();
        tri_pct += 100.0 * (1.0 - vis_tris as f64 / total_tris as f64);
        leaves += 1;
    }
    let nc = leaves.max(1) as f64;
    let ms: Vec<f64> = flat.iter().map(|(_, _, c)| c.ms).collect();
    let n_objects = objects.len();
    PvsDocument {
        format: FORMAT.into(),
        version: VERSION,
        scene: source,
        settings: PvsSettings {
            backend: result.backend.clone(),
            bake: BakeSettings {
                sweep: if result.sweep {
                    SweepChoice::On
                } else {
                    SweepChoice::Off
                },
                sampling: if result.sampling {
                    SweepChoice::On
                } else {
                    SweepChoice::Off
                },
                rsf: if result.rsf {
                    SweepChoice::On
                } else {
                    SweepChoice::Off
                },
                ..settings.clone()
            },
        },
        objects,
        cells: flat
            .iter()
            .map(|&(b, parent, c)| PvsCell {
                min: b.min.to_array(),
                max: b.max.to_array(),
                visible: c.visible.clone(),
                ms: c.ms,
                parent: parent.map(|p| p as u32),
                cullers: if result.sampling {
                    result
                        .cullers
                        .iter()
                        .zip(&c.cullers)
                        .map(|(name, s)| crate::pvs::PvsCellCuller {
                            name: (*name).to_string(),
                            hidden: s.hidden,
                            ms: s.ms,
                            points: s.work.points,
                            finest_eps: s.work.finest_eps,
                            levels: s.work.levels.clone(),
                        })
                        .collect()
                } else {
                    Vec::new()
                },
            })
            .collect(),
        summary: Some(PvsSummary {
            cells: flat.len(),
            objects: n_objects,
            triangles,
            occluder_triangles: result.occluder_triangles,
            degenerate_triangles: result.degenerate_triangles,
            backend: result.backend.clone(),
            adapter: result.adapter.clone(),
            objects_culled_percent: obj_pct / nc,
            triangles_culled_percent: tri_pct / nc,
            median_ms_per_cell: median(&ms),
            total_seconds: result.seconds,
            cullers: culler_summary(result),
            alpha_cards: result.cards.map(|c| crate::pvs::PvsCardSummary {
                triangles: c.triangles,
                polygons: c.polygons,
                opaque_share: if c.card_area > 0.0 {
                    c.opaque_area / c.card_area
                } else {
                    0.0
                },
            }),
        }),
        split: None,
    }
}

/// The cullers' mean accounts per cell, for the PVS document's summary.
pub fn culler_summary(result: &BakeResult) -> Vec<PvsCullerSummary> {
    let nc = result.cells.len().max(1) as f64;
    (result.cullers.iter().enumerate())
        .map(|(k, name)| {
            let sum = |f: &dyn Fn(&CullerStats) -> f64| -> f64 {
                result
                    .cells
                    .iter()
                    .filter_map(|c| c.cullers.get(k))
                    .map(f)
                    .sum::<f64>()
                    / nc
            };
            PvsCullerSummary {
                name: (*name).to_string(),
                hidden: sum(&|s| s.hidden as f64),
                only: sum(&|s| s.only as f64),
                ms: sum(&|s| s.ms),
                planes: sum(&|s| s.work.planes as f64),
                points: sum(&|s| s.work.points as f64),
                finest_eps: result
                    .cells
                    .iter()
                    .filter_map(|c| c.cullers.get(k).and_then(|s| s.work.finest_eps))
                    .reduce(f64::min),
                cpu_fallback: result
                    .cells
                    .iter()
                    .find_map(|c| c.cullers.get(k).and_then(|s| s.work.cpu_fallback.clone())),
                levels: level_summary(
                    &result
                        .cells
                        .iter()
                        .filter_map(|c| c.cullers.get(k))
                        .map(|s| &s.work.levels[..])
                        .filter(|l| !l.is_empty())
                        .collect::<Vec<_>>(),
                ),
            }
        })
        .collect()
}

/// The mean cost curve of the cells with one: level `k` is the mean over them of what a
/// budget that ran out after level `k` gives, a cell that stopped before it counting with its
/// last level; ε is the largest.
fn level_summary(curves: &[&[crate::pvs::SamplingLevel]]) -> Vec<crate::pvs::PvsLevelSummary> {
    let levels = curves.iter().map(|c| c.len()).max().unwrap_or(0);
    let n = curves.len().max(1) as f64;
    (0..levels)
        .map(|k| {
            let at = |c: &&[crate::pvs::SamplingLevel]| c[k.min(c.len() - 1)];
            let mean = |f: &dyn Fn(&crate::pvs::SamplingLevel) -> f64| {
                curves.iter().map(|c| f(&at(c))).sum::<f64>() / n
            };
            crate::pvs::PvsLevelSummary {
                eps: curves.iter().map(|c| at(c).eps).fold(0.0, f64::max),
                resolution: curves.iter().map(|c| at(c).resolution).max().unwrap_or(0),
                points: mean(&|l| l.points as f64),
                seconds: mean(&|l| l.seconds),
                hidden: mean(&|l| f64::from(l.hidden)),
                probe_only: mean(&|l| f64::from(u8::from(l.probe_only))),
                probe_hidden: probe_mean(curves, k, |l| l.probe_hidden),
                probe_cell_hidden: probe_mean(curves, k, |l| l.probe_cell_hidden.map(f64::from)),
                probe_objects: probe_mean(curves, k, |l| l.probe_objects.map(f64::from)),
                probe_rects: probe_mean(curves, k, |l| l.probe_rects.map(f64::from)),
                probe_cost: probe_mean(curves, k, |l| l.probe_cost),
                pilot_saving: probe_mean(curves, k, |l| l.pilot_saving),
            }
        })
        .collect()
}

/// The mean of a probe figure of level `k` over the cells whose level `k` had a probe.
fn probe_mean(
    curves: &[&[crate::pvs::SamplingLevel]],
    k: usize,
    f: impl Fn(&crate::pvs::SamplingLevel) -> Option<f64>,
) -> Option<f64> {
    let v: Vec<f64> = curves
        .iter()
        .filter_map(|c| c.get(k).and_then(&f))
        .collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}
