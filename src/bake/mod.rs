//! Baking: the settings ([`BakeSettings`]), the bake of every cell ([`bake`]) and its PVS
//! document ([`to_document`]). A scene is prepared once ([`Prepared`], `prepare.rs`); every
//! cell — or every sub-cell of it with `subcell` — then runs the pipeline of cullers
//! (`pipeline.rs`, [`Culler`]): today extended projections on separate planes or the occlusion
//! sweep (`planes.rs`). Cells run in parallel (rayon).

mod pipeline;
mod planes;
mod prepare;
mod sampling;

pub use pipeline::{CullState, Culler, CullerStats, CullerWork, cullers};
pub use planes::{PlaneCuller, SWEEP_TEST_REACH};
pub use prepare::{
    PIECE_LEVELS, PIECE_MIN_TRIANGLES, Prepared, SAMPLING_AUTO_NOTE, SMALL_OCCLUDER_CELLS,
    SMALL_OCCLUDER_SHARE, choose_sweep, split_cell,
};
pub use sampling::{SamplerData, SamplingCuller};

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
}

/// One cell's outcome.
#[derive(Clone, Debug, PartialEq)]
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
}

/// A whole bake's outcome.
#[derive(Clone, Debug)]
pub struct BakeResult {
    /// Per cell, in the order of the cells given to the bake.
    pub cells: Vec<CellResult>,
    /// The backend's name ([`RasterBackend::name`], e.g. `cpu` or `gpu`).
    pub backend: String,
    /// The GPU adapter's description, `None` for the CPU backend.
    pub adapter: Option<String>,
    /// Triangles used as occluders (opaque, selected, not degenerate).
    pub occluder_triangles: usize,
    /// Zero-area triangles skipped.
    pub degenerate_triangles: usize,
    /// Wall time of the whole bake (preparation included), in seconds.
    pub seconds: f64,
    /// Whether the bake swept, and why (for the summary).
    pub sweep: bool,
    /// Why the bake swept or not, one human-readable line.
    pub sweep_reason: String,
    /// Whether cells ran the shrunk-occluder sampler.
    pub sampling: bool,
    /// Why the sampler ran or not, and its finest ε.
    pub sampling_reason: String,
    /// The names of the cullers every cell ran, in order.
    pub cullers: Vec<&'static str>,
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
    let start = Instant::now();
    let prepared = Prepared::new(scene, settings, cells)?;
    let done = std::sync::atomic::AtomicUsize::new(0);
    let cells_out: Result<Vec<CellResult>, BakeError> = cells
        .par_iter()
        .enumerate()
        .map(|(ci, c)| {
            let r = match observe {
                None => prepared.cell(c, backend),
                Some(f) => {
                    let mut k = 0;
                    prepared.cell_observed(c, backend, &mut |job, map, hdm| {
                        f(ci, k, job, map, hdm);
                        k += 1;
                    })
                }
            };
            let k = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            if let Some(p) = progress {
                p(k);
            }
            r
        })
        .collect();
    Ok(BakeResult {
        cells: cells_out?,
        backend: backend.name().to_string(),
        adapter: backend.adapter(),
        occluder_triangles: prepared.occluders.stats.triangles,
        degenerate_triangles: scene.degenerate_triangles(),
        seconds: start.elapsed().as_secs_f64(),
        sweep: prepared.sweep,
        sweep_reason: prepared.sweep_reason.clone(),
        sampling: prepared.sampling,
        sampling_reason: prepared.sampling_reason.clone(),
        cullers: prepared.culler_names(),
    })
}

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
    let tri_count = |o: u32| scene.objects[o as usize].triangles.len();
    let total_tris = scene.triangles.len().max(1);
    let n_obj = scene.objects.len().max(1);
    let mut obj_pct = 0.0;
    let mut tri_pct = 0.0;
    for c in &result.cells {
        obj_pct += 100.0 * (1.0 - c.visible.len() as f64 / n_obj as f64);
        let vis_tris: usize = c.visible.iter().map(|&o| tri_count(o)).sum();
        tri_pct += 100.0 * (1.0 - vis_tris as f64 / total_tris as f64);
    }
    let nc = result.cells.len().max(1) as f64;
    let ms: Vec<f64> = result.cells.iter().map(|c| c.ms).collect();
    PvsDocument {
        format: FORMAT.into(),
        version: VERSION,
        scene: scene.source.display().to_string(),
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
                ..settings.clone()
            },
        },
        objects: object_table(scene),
        cells: cells
            .iter()
            .zip(&result.cells)
            .map(|(b, c)| PvsCell {
                min: b.min.to_array(),
                max: b.max.to_array(),
                visible: c.visible.clone(),
                ms: c.ms,
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
                        })
                        .collect()
                } else {
                    Vec::new()
                },
            })
            .collect(),
        summary: Some(PvsSummary {
            cells: cells.len(),
            objects: scene.objects.len(),
            triangles: scene.triangles.len(),
            occluder_triangles: result.occluder_triangles,
            degenerate_triangles: result.degenerate_triangles,
            backend: result.backend.clone(),
            adapter: result.adapter.clone(),
            objects_culled_percent: obj_pct / nc,
            triangles_culled_percent: tri_pct / nc,
            median_ms_per_cell: median(&ms),
            total_seconds: result.seconds,
            cullers: culler_summary(result),
        }),
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
            }
        })
        .collect()
}
