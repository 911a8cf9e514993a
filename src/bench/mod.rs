//! `umbrasweep bench`: bakes a fixed set of scenes with each backend, validates every baked
//! cell against ray-sampled ground truth, and prints one table (see `docs/bench.md`).
//!
//! The scenes are generated in memory — a city ([`CityOptions`] 12×12 blocks, street cells),
//! the coarse forest (path cells; 300 trees with `--quick`, all 1,500 otherwise), a boxfield —
//! and, when the shared scene folder exists (`../shared/scenes` from the current directory,
//! or `--shared DIR`), the real ones: `urban/sionna_munich.glb` and `urban/sionna_etoile.glb`
//! (cells from [`free_cells`], 4×2×4 m at 1 m), `levels/zdm2.obj`
//! (a Cube 2 map in Cube units: cells 64×32×64 at 16 above the lowest point) and a small forest
//! of `foliage/tree_poinciana.glb` instances ([`forest_of_models`]).
//!
//! Every backend bakes the same cells (the GPU backend the first `--gpu-cells` of them); the
//! sampled visible set of a cell is computed once and compared with each backend's PVS.
//! Progress lines go to [`BenchOptions::progress`] (the command prints them on stderr, the
//! table on stdout and the rows to `--json` if asked: `src/cli_bench.rs`). Benchmarks are
//! measurements, not tests: nothing here asserts a timing.
//!
//! `--foliage` runs the foliage study instead ([`foliage`]); it shares this module's
//! validation (`sample`, `score`) and table layout (`markdown_table`).

pub mod foliage;

use crate::backend::RasterBackend;
use crate::backend::cpu::CpuBackend;
use crate::backend::gpu::GpuBackend;
use crate::bake::{BakeResult, BakeSettings, bake, median};
use crate::cells::free_cells;
use crate::generate::{
    BoxfieldOptions, CityOptions, ForestOptions, TreeModel, boxfield, city, forest,
    forest_of_models,
};
use crate::geom::Aabb;
use crate::pvs::PvsCell;
use crate::scene::Scene;
use crate::validate::{CellSample, SceneRays, cell_report, sample_cell};
use glam::Vec3;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Which backends the benchmark runs (`umbrasweep bench --backend`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BenchBackend {
    /// The CPU backend only.
    Cpu,
    /// The GPU backend only (an error when no adapter exists).
    Gpu,
    /// The CPU backend, and the GPU backend when an adapter exists.
    #[default]
    All,
}

/// A progress line receiver: every line the benchmark reports while it runs (`bench: …`,
/// false culls with their witness rays). `umbrasweep bench` prints them on stderr.
pub type ProgressLog = fn(&str);

/// Options of the benchmark ([`collect`]) and of the foliage study ([`foliage::collect`]):
/// the settings of `umbrasweep bench` without its output (`--json`) and its choice of study
/// (`--foliage`). [`Default`] gives the command's defaults.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    /// A small version that runs in a few minutes: 10 cells per scene, 3 on the GPU, a forest
    /// of 300 trees and 6 model trees (scene bench only).
    pub quick: bool,
    /// Cells per scene (default 50, 10 with `quick` or in the foliage study).
    pub cells: Option<usize>,
    /// Cells per scene on the GPU backend, the first of the CPU's (default 10, 3 with
    /// `quick`).
    pub gpu_cells: Option<usize>,
    /// Validation rays per cell (default 1,000,000; 200,000 in the foliage study).
    pub rays: Option<u64>,
    /// Seed of the generated scenes, of the free-space cells and of the validation rays
    /// (default 1).
    pub seed: u64,
    /// Backends to run (the foliage study: the CPU unless [`BenchBackend::Gpu`]).
    pub backend: BenchBackend,
    /// The shared scene folder (default: `../shared/scenes` when it exists).
    pub shared: Option<PathBuf>,
    /// Only these scenes: city, forest, boxfield, munich, etoile, zdm2, poinciana (all when
    /// `None`; scene bench only).
    pub scenes: Option<Vec<String>>,
    /// Also write every bake's PVS document to `DIR/SCENE-BACKEND.json` (the folder is
    /// created if needed; scene bench only).
    pub pvs_out: Option<PathBuf>,
    /// Only these foliage studies ([`foliage::STUDIES`]; all when `None`).
    pub foliage_studies: Option<Vec<String>>,
    /// Cells baked by the fine forest's sub-cell variants (spread over its cells).
    pub foliage_subcell_cells: usize,
    /// Cells of the paper's forest.
    pub foliage_paper_cells: usize,
    /// Jacaranda trees in the jacaranda study.
    pub foliage_model_trees: u32,
    /// Trees of every procedural foliage forest (instead of 1,500 and 7,750), for tests.
    pub foliage_trees: Option<u32>,
    /// Sample points per cell of the foliage study's sampler rows (`--sampling-budget`).
    pub foliage_sampling_budget: u64,
    /// The sampler rows' `--sampling-max-eps` (levels coarser than this are split without
    /// being sampled), if any.
    pub foliage_sampling_max_eps: Option<f64>,
    /// Whether the sampler rows run the tuck pass (`--sampling-tuck`).
    pub foliage_sampling_tuck: bool,
    /// The sampler rows' finest ε (`--sampling-eps`), if any.
    pub foliage_sampling_eps: Option<f64>,
    /// The sampler rows' refinement levels (`--sampling-levels`), if any.
    pub foliage_sampling_levels: Option<u32>,
    /// `--hunt-rays`: every row's PVS is also hunted (`validate --hunt`) with this many rays
    /// per cell, if any.
    pub hunt_rays: Option<u64>,
    /// `--confirm-rays`: every row's PVS is also measured against a fuller visible set
    /// (`validate --confirm-rays`) with this many more rays per cell, if any.
    pub confirm_rays: Option<u64>,
    /// The foliage study's sampler cells save their progress here
    /// ([`crate::bake::SamplerCheckpoints`], files `STUDY-ROW.sampler-*`, kept when a cell
    /// finishes), and a run with the same folder and options replays what they recorded: a
    /// killed bench run again redoes no finished sampler cell and resumes the one it was in.
    /// `None`: no checkpoints.
    pub checkpoint_dir: Option<PathBuf>,
    /// Seconds at least between two saves of one cell's checkpoint (with `checkpoint_dir`).
    pub checkpoint_seconds: f64,
    /// Receives the progress lines; none are reported when `None`.
    pub progress: Option<ProgressLog>,
    /// Ray space factorization in the scene bench's bakes: chosen per scene (the default, as
    /// `bake`), forced on or off, to measure what it adds.
    pub rsf: crate::settings::SweepChoice,
    /// How the GPU backend makes occluders' Projections
    /// ([`GpuProjection`](crate::backend::gpu::GpuProjection)).
    pub gpu_projection: Option<crate::backend::gpu::GpuProjection>,
    /// Ray space factorization's charts on the GPU backend's device rather than the CPU
    /// ([`GpuBackend::set_rsf_on_gpu`](crate::backend::gpu::GpuBackend::set_rsf_on_gpu)).
    pub rsf_on_gpu: bool,
    /// Maps read back and occludees tested on the CPU rather than on the device
    /// ([`GpuBackend::set_tests_on_device`](crate::backend::gpu::GpuBackend::set_tests_on_device)).
    pub tests_on_cpu: bool,
    /// Only the occlusion sweep's maps read back rather than kept on the device
    /// ([`GpuBackend::set_keep_sweep_maps`](crate::backend::gpu::GpuBackend::set_keep_sweep_maps)).
    pub sweep_maps_on_cpu: bool,
    /// Occludee boxes sent with their tests rather than kept on the device
    /// ([`GpuBackend::set_resident_boxes`](crate::backend::gpu::GpuBackend::set_resident_boxes)).
    pub boxes_inline: bool,
    /// Counted occluders' points sent with their planes rather than the scene's parts kept
    /// on the device
    /// ([`GpuBackend::set_resident_parts`](crate::backend::gpu::GpuBackend::set_resident_parts)).
    pub occluders_inline: bool,
    /// Pixels per occludee test asked of the device; `None` for the backend's default
    /// ([`GpuBackend::set_pixels_per_device_test`](crate::backend::gpu::GpuBackend::set_pixels_per_device_test)).
    pub pixels_per_device_test: Option<usize>,
    /// Device memory the sampler's GPU samplers may take together; `None` for the backend's
    /// default
    /// ([`GpuBackend::set_sampler_memory`](crate::backend::gpu::GpuBackend::set_sampler_memory)).
    pub gpu_sampler_memory: Option<u64>,
}

impl Default for BenchOptions {
    fn default() -> Self {
        BenchOptions {
            quick: false,
            cells: None,
            gpu_cells: None,
            rays: None,
            seed: 1,
            backend: BenchBackend::All,
            shared: None,
            scenes: None,
            pvs_out: None,
            foliage_studies: None,
            foliage_subcell_cells: foliage::DEFAULT_SUBCELL_CELLS,
            foliage_paper_cells: foliage::DEFAULT_PAPER_CELLS,
            foliage_model_trees: foliage::DEFAULT_MODEL_TREES,
            foliage_trees: None,
            foliage_sampling_budget: foliage::SAMPLING_BENCH_POINTS,
            foliage_sampling_max_eps: None,
            foliage_sampling_tuck: false,
            foliage_sampling_eps: None,
            foliage_sampling_levels: None,
            hunt_rays: None,
            confirm_rays: None,
            gpu_projection: None,
            rsf_on_gpu: false,
            tests_on_cpu: false,
            sweep_maps_on_cpu: false,
            boxes_inline: false,
            occluders_inline: false,
            pixels_per_device_test: None,
            gpu_sampler_memory: None,
            checkpoint_dir: None,
            checkpoint_seconds: 60.0,
            progress: None,
            rsf: crate::settings::SweepChoice::Auto,
        }
    }
}

/// Reports one progress line to [`BenchOptions::progress`], formatted like `format!`.
macro_rules! say {
    ($log:expr, $($arg:tt)*) => {
        if let Some(log) = $log {
            log(&format!($($arg)*));
        }
    };
}
pub(crate) use say;

/// Errors of the benchmark and of the foliage study. Each names the option or the file at
/// fault.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// A count option is 0 (`flag` names it, e.g. `--cells and --rays`, `--foliage-paper-cells`):
    /// give at least 1.
    #[error("{0} must be at least 1")]
    Zero(&'static str),
    /// An option's value is out of range (`flag` names it; `why` says what it must be).
    #[error("{flag} {value}: {why}")]
    BadValue {
        /// The option.
        flag: &'static str,
        /// The value given.
        value: String,
        /// What it must be.
        why: &'static str,
    },
    /// [`BenchOptions::scenes`] names a scene the benchmark does not have.
    #[error("--scenes {}: unknown scene (one of {})", .0, SCENES.join(", "))]
    UnknownScene(String),
    /// [`BenchOptions::foliage_studies`] names a study that does not exist.
    #[error("--foliage-studies {}: unknown study (one of {})", .0, foliage::STUDIES.join(", "))]
    UnknownStudy(String),
    /// [`BenchOptions::shared`] is not a folder.
    #[error("--shared {}: not a directory", .0.display())]
    NotADirectory(PathBuf),
    /// The [`BenchOptions::pvs_out`] folder cannot be created.
    #[error("--pvs-out {}: cannot create the folder", path.display())]
    PvsOut {
        /// The folder.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The [`BenchOptions::checkpoint_dir`] folder cannot be created.
    #[error("--checkpoint-dir {}: cannot create the folder", path.display())]
    CheckpointDir {
        /// The folder.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A PVS document cannot be written into the [`BenchOptions::pvs_out`] folder.
    #[error("{0}")]
    WritePvs(crate::pvs::PvsWriteError),
    /// [`BenchBackend::Gpu`] was asked but no GPU backend could be made.
    #[error("--backend gpu")]
    Gpu(#[source] crate::backend::BackendError),
    /// A scene file of the shared folder exists but cannot be loaded.
    #[error("{}", path.display())]
    Scene {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: crate::scene::SceneError,
    },
    /// A generated scene or forest cannot be made.
    #[error(transparent)]
    Generate(#[from] crate::generate::GenError),
    /// A bake failed (the scene bench stops; the foliage study reports it and goes on).
    #[error("{scene}: bake on {backend}")]
    Bake {
        /// The scene.
        scene: String,
        /// The backend's name.
        backend: String,
        /// Why.
        #[source]
        source: crate::bake::BakeError,
    },
}

/// One row of the table: one scene baked by one backend.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BenchRow {
    /// Scene name (`city`, `forest`, `sionna_munich`, …).
    pub scene: String,
    /// Triangles in the scene.
    pub triangles: usize,
    /// Objects in the scene.
    pub objects: usize,
    /// Cells baked and validated.
    pub cells: usize,
    /// `cpu` or `gpu`.
    pub backend: String,
    /// The GPU adapter, if any.
    pub adapter: Option<String>,
    /// On the GPU backend, how it made occluders' Projections (`clipped` or `counting`).
    #[serde(default)]
    pub gpu_projection: Option<String>,
    /// Median bake time per cell (the bake's per-cell `ms`).
    pub median_ms_per_cell: f64,
    /// Median time to sample one cell's visible set with `rays_per_cell` rays.
    pub validate_ms_per_cell: f64,
    /// Mean over cells of the percentage of objects culled.
    pub objects_culled_percent: f64,
    /// Mean over cells of the percentage of triangles culled.
    pub triangles_culled_percent: f64,
    /// Mean over cells of |PVS| / |VS| (cells with an empty VS left out).
    pub pvs_over_vs: Option<f64>,
    /// Objects sampled visible but missing from the PVS, over all cells (must be 0).
    pub false_culls: usize,
    /// Mean projection planes rendered per cell.
    pub planes_per_cell: f64,
    /// Validation rays per cell.
    pub rays_per_cell: u64,
    /// The process's peak resident memory during the bake, MiB (the loaded scene and the
    /// validator's ray index included; `VmHWM`, reset before the bake; None where that is
    /// not possible).
    pub peak_mib: Option<f64>,
    /// Per cell, what the backend itself did (the GPU backend; absent for the CPU's).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub device: Option<DeviceRow>,
    /// Per culler of the pipeline, in its order: its name and the median over the cells of
    /// the milliseconds it ran.
    pub culler_ms_per_cell: Vec<CullerMs>,
    /// `--hunt-rays` only: the row's PVS hunted as `validate --hunt` does.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hunt: Option<RowHunt>,
    /// `--confirm-rays` only: the row's PVS against a fuller visible set, as
    /// `validate --confirm-rays` measures it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub confirm: Option<RowConfirm>,
}

/// A row's PVS hunted (`--hunt-rays`; [`crate::validate::CheckOptions::hunt`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RowHunt {
    /// Rays per cell.
    pub rays_per_cell: u64,
    /// (cell, culled object) pairs hunted.
    pub hunted_objects: u64,
    /// The fewest rays any culled object of any cell got.
    pub rays_per_culled_object: u64,
    /// Culled objects a hunting ray saw (or that overlap their cell), over the row's cells.
    pub false_culls: usize,
}

/// A row's PVS against the sampled visible set plus the PVS objects confirming rays saw
/// (`--confirm-rays`; [`crate::validate::CheckOptions::confirm_rays`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RowConfirm {
    /// Confirming rays per cell (beyond the validation rays).
    pub confirm_rays: u64,
    /// Objects confirmed visible, over the row's cells.
    pub confirmed_objects: u64,
    /// Mean over the cells of |VS| + confirmed (the validation's own sample: `validate`'s
    /// streams, cell by cell of the row, as `validate --confirm-rays` on its PVS gives).
    pub vs_plus: f64,
    /// Mean over the cells of |PVS| / (|VS| + confirmed).
    pub pvs_over_confirmed_vs: Option<f64>,
    /// Culled objects the confirmation's sample or a confirming ray saw, over the row's
    /// cells: false culls, as `validate --confirm-rays` reports them.
    pub false_culls: usize,
}

/// `--hunt-rays` and `--confirm-rays`: checks a row's PVS document as `validate --hunt` and
/// `validate --confirm-rays` would (`rays`: the validation rays per cell the confirmation's
/// sample casts), logging every false cull the hunt finds under `label`.
pub(crate) fn harder_checks(
    index: &SceneRays,
    scene: &Scene,
    doc: &crate::pvs::PvsDocument,
    rays: u64,
    args: &BenchOptions,
    label: &str,
) -> (Option<RowHunt>, Option<RowConfirm>) {
    use crate::validate::{CheckOptions, check_with};
    let t = Instant::now();
    let log_false_culls = |r: &crate::validate::Report, check: &str| {
        for (i, c) in r.cells.iter().enumerate() {
            for f in &c.false_culls {
                say!(
                    args.progress,
                    "bench: FALSE CULL ({check}) {label} cell {i} {:?}–{:?}: object {} {:?}, \
                     ray origin {:?} direction {:?}",
                    c.min,
                    c.max,
                    f.object,
                    f.name,
                    f.origin,
                    f.direction
                );
            }
        }
    };
    // The document was made from this scene, so `check_input` cannot refuse it.
    let hunt = args.hunt_rays.and_then(|hunt_rays| {
        let opts = CheckOptions {
            rays: hunt_rays,
            seed: args.seed,
            hunt: true,
            ..CheckOptions::default()
        };
        let r = check_with(index, scene, doc, &opts).ok()?;
        log_false_culls(&r, "hunt");
        Some(RowHunt {
            rays_per_cell: hunt_rays,
            hunted_objects: r.hunted_objects.unwrap_or(0),
            rays_per_culled_object: r.rays_per_culled_object.unwrap_or(0),
            false_culls: r.false_culls,
        })
    });
    let confirm = args.confirm_rays.and_then(|confirm_rays| {
        let opts = CheckOptions {
            rays,
            seed: args.seed,
            confirm_rays,
            ..CheckOptions::default()
        };
        let r = check_with(index, scene, doc, &opts).ok()?;
        log_false_culls(&r, "confirm");
        let n = r.cells.len().max(1) as f64;
        let ratios: Vec<f64> = r
            .cells
            .iter()
            .filter_map(|c| c.pvs_over_confirmed_vs)
            .collect();
        Some(RowConfirm {
            confirm_rays,
            confirmed_objects: r.confirmed_objects.unwrap_or(0),
            vs_plus: r
                .cells
                .iter()
                .map(|c| (c.vs + c.confirmed.as_ref().map_or(0, Vec::len)) as f64)
                .sum::<f64>()
                / n,
            pvs_over_confirmed_vs: (!ratios.is_empty())
                .then(|| ratios.iter().sum::<f64>() / ratios.len() as f64),
            false_culls: r.false_culls,
        })
    });
    if hunt.is_some() || confirm.is_some() {
        say!(
            args.progress,
            "bench: {label}: checked{}{} in {:.1} s",
            hunt.as_ref().map_or(String::new(), |h| format!(
                ", hunt {} culled objects at >= {} rays: {} false culls",
                h.hunted_objects, h.rays_per_culled_object, h.false_culls
            )),
            confirm.as_ref().map_or(String::new(), |c| format!(
                ", |VS+| {:.1}, PVS/VS+ {}, {} false culls",
                c.vs_plus,
                c.pvs_over_confirmed_vs
                    .map_or("–".into(), |v| format!("{v:.2}")),
                c.false_culls
            )),
            t.elapsed().as_secs_f64()
        );
    }
    (hunt, confirm)
}

/// One culler's median time per cell in a [`BenchRow`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CullerMs {
    /// The culler's name ([`crate::bake::CULLER_NAMES`]).
    pub culler: String,
    /// The median over the cells of its milliseconds.
    pub median_ms: f64,
}

/// Per cell, what a backend with a device did during one scene's bake (means over its cells).
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct DeviceRow {
    /// Render passes.
    pub passes_per_cell: f64,
    /// KiB sent to the device.
    pub kib_up_per_cell: f64,
    /// KiB read back from it.
    pub kib_down_per_cell: f64,
    /// Depth Maps read back, and sweep planes' maps kept on the device instead.
    pub maps_down_per_cell: f64,
    /// See `maps_down_per_cell`.
    pub maps_kept_per_cell: f64,
    /// Wall ms of the CPU's setup of the jobs.
    pub setup_ms_per_cell: f64,
    /// Wall ms of the device's section, from the first upload to the last read-back.
    pub device_ms_per_cell: f64,
    /// GPU ms of the render passes from the device's timestamps (absent without them).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pass_ms_per_cell: Option<f64>,
}

impl DeviceRow {
    /// The means over `cells` cells of what `c` counts.
    pub fn of(c: &crate::backend::BackendCounters, cells: usize) -> DeviceRow {
        let n = cells.max(1) as f64;
        DeviceRow {
            passes_per_cell: c.passes as f64 / n,
            kib_up_per_cell: c.bytes_uploaded as f64 / 1024.0 / n,
            kib_down_per_cell: c.bytes_read_back as f64 / 1024.0 / n,
            maps_down_per_cell: c.maps_read_back as f64 / n,
            maps_kept_per_cell: c.maps_kept as f64 / n,
            setup_ms_per_cell: c.setup.as_secs_f64() * 1e3 / n,
            device_ms_per_cell: c.gpu.as_secs_f64() * 1e3 / n,
            pass_ms_per_cell: c.pass_time.map(|t| t.as_secs_f64() * 1e3 / n),
        }
    }
}

/// A whole benchmark run: the `--json` document.
#[derive(Clone, Debug, Serialize)]
pub struct Bench {
    /// `"umbrasweep-bench"`.
    pub format: String,
    /// `--quick` was given.
    pub quick: bool,
    /// Validation rays per cell.
    pub rays_per_cell: u64,
    /// Cells per scene on the CPU backend (fewer when a scene has fewer).
    pub cells: usize,
    /// Cells per scene on the GPU backend (the first of the CPU's).
    pub gpu_cells: usize,
    /// Seed of scenes, cells and rays.
    pub seed: u64,
    /// Worker threads (rayon).
    pub threads: usize,
    /// One row per scene and backend.
    pub rows: Vec<BenchRow>,
    /// Scenes or backends skipped or failed, and why.
    pub skipped: Vec<String>,
    /// Wall-clock time of the whole run, seconds.
    pub seconds: f64,
    /// Hunting rays per cell of every row, if given (`--hunt-rays`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hunt_rays: Option<u64>,
    /// Confirming rays per cell of every row, if given (`--confirm-rays`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub confirm_rays: Option<u64>,
}

/// The scenes of the benchmark, in table order.
const SCENES: [&str; 7] = [
    "city",
    "forest",
    "boxfield",
    "munich",
    "etoile",
    "zdm2",
    "poinciana",
];

/// A scene ready to bake.
struct BenchScene {
    name: String,
    scene: Scene,
    cells: Vec<Aabb>,
}

/// Settings after defaults.
struct Plan {
    cells: usize,
    gpu_cells: usize,
    rays: u64,
    shared: Option<PathBuf>,
    pvs_out: Option<PathBuf>,
}

impl Plan {
    fn new(args: &BenchOptions) -> Result<Plan, BenchError> {
        let q = args.quick;
        let cells = args.cells.unwrap_or(if q { 10 } else { 50 });
        let gpu_cells = args.gpu_cells.unwrap_or(if q { 3 } else { 10 }).min(cells);
        let rays = args.rays.unwrap_or(1_000_000);
        if cells == 0 || rays == 0 {
            return Err(BenchError::Zero("--cells and --rays"));
        }
        if args.hunt_rays == Some(0) || args.confirm_rays == Some(0) {
            return Err(BenchError::Zero("--hunt-rays and --confirm-rays"));
        }
        let shared = shared_folder(args)?;
        if let Some(list) = &args.scenes
            && let Some(bad) = list.iter().find(|s| !SCENES.contains(&s.as_str()))
        {
            return Err(BenchError::UnknownScene(bad.clone()));
        }
        if let Some(dir) = &args.pvs_out {
            std::fs::create_dir_all(dir).map_err(|source| BenchError::PvsOut {
                path: dir.clone(),
                source,
            })?;
        }
        Ok(Plan {
            cells,
            gpu_cells,
            rays,
            shared,
            pvs_out: args.pvs_out.clone(),
        })
    }
}

/// The shared scene folder: `--shared DIR` (an error when it is not a folder), else
/// `../shared/scenes` when it exists.
///
/// # Errors
/// `--shared` naming something that is not a folder.
pub(crate) fn shared_folder(args: &BenchOptions) -> Result<Option<PathBuf>, BenchError> {
    Ok(match &args.shared {
        Some(d) if d.is_dir() => Some(d.clone()),
        Some(d) => return Err(BenchError::NotADirectory(d.clone())),
        None => Some(PathBuf::from("../shared/scenes")).filter(|d| d.is_dir()),
    })
}

/// The file `rel` of the shared scene folder `shared`; `Err(reason)` (naming `name`) when
/// there is no folder or no such file.
pub(crate) fn shared_file(shared: Option<&Path>, name: &str, rel: &str) -> Result<PathBuf, String> {
    match shared {
        None => Err(format!(
            "{name}: skipped, no shared scene folder (../shared/scenes or --shared DIR)"
        )),
        Some(d) => {
            let p = d.join(rel);
            if p.is_file() {
                Ok(p)
            } else {
                Err(format!("{name}: skipped, {} is missing", p.display()))
            }
        }
    }
}

/// The message of a caught panic.
pub(crate) fn panic_message(panic: &(dyn std::any::Any + Send)) -> String {
    panic
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_default()
}

/// Builds scene `name`; `Ok(Err(reason))` when it needs the shared folder or a file in it
/// that is absent.
fn build(
    name: &str,
    args: &BenchOptions,
    plan: &Plan,
) -> Result<Result<BenchScene, String>, BenchError> {
    let n = plan.cells;
    let seed = args.seed;
    let generated = |g: crate::generate::Generated, name: &str| BenchScene {
        name: name.into(),
        scene: g.to_scene(name),
        cells: g.cells,
    };
    let shared_file = |rel: &str| shared_file(plan.shared.as_deref(), name, rel);
    let load = |p: &Path| {
        crate::scene::load(p).map_err(|source| BenchError::Scene {
            path: p.to_path_buf(),
            source,
        })
    };
    let free = |scene: &Scene, size: Vec3, height: f32| {
        let bounds: Vec<Aabb> = scene.objects.iter().map(|o| o.bounds).collect();
        free_cells(&bounds, n, size, height, seed)
    };
    Ok(Ok(match name {
        "city" => generated(
            city(&CityOptions {
                seed,
                max_cells: Some(n),
                ..CityOptions::with_blocks(12, 12)
            })?,
            "city",
        ),
        "forest" => generated(
            forest(&ForestOptions {
                seed,
                trees: if args.quick { 300 } else { 1500 },
                max_cells: Some(n),
                ..ForestOptions::coarse()
            })?,
            "forest",
        ),
        "boxfield" => generated(
            boxfield(&BoxfieldOptions {
                seed,
                max_cells: Some(n),
                ..BoxfieldOptions::default()
            })?,
            "boxfield",
        ),
        "munich" | "etoile" => {
            let file = format!("urban/sionna_{name}.glb");
            let path = match shared_file(&file) {
                Ok(p) => p,
                Err(why) => return Ok(Err(why)),
            };
            let scene = load(&path)?;
            let cells = free(&scene, Vec3::new(4.0, 2.0, 4.0), 1.0);
            BenchScene {
                name: format!("sionna_{name}"),
                scene,
                cells,
            }
        }
        "zdm2" => {
            let path = match shared_file("levels/zdm2.obj") {
                Ok(p) => p,
                Err(why) => return Ok(Err(why)),
            };
            let scene = load(&path)?;
            // Cube 2 units (a player is ~16 tall; the map spans ~870 × 324 × 610).
            let cells = free(&scene, Vec3::new(64.0, 32.0, 64.0), 16.0);
            BenchScene {
                name: "zdm2".into(),
                scene,
                cells,
            }
        }
        "poinciana" => {
            let path = match shared_file("foliage/tree_poinciana.glb") {
                Ok(p) => p,
                Err(why) => return Ok(Err(why)),
            };
            let model = TreeModel::from_scene(&load(&path)?);
            let g = forest_of_models(
                &ForestOptions {
                    seed,
                    trees: if args.quick { 6 } else { 16 },
                    area_per_tree: None,
                    max_cells: Some(n),
                    ..ForestOptions::default()
                },
                &model,
            )?;
            generated(g, "poinciana_forest")
        }
        other => return Err(BenchError::UnknownScene(other.into())),
    }))
}

/// The GPU backend with `args`' projection and charts.
///
/// # Errors
/// [`BenchError::Gpu`] without an adapter, or for a projection the device cannot run.
pub(crate) fn gpu_backend(args: &BenchOptions) -> Result<GpuBackend, BenchError> {
    let mut g = GpuBackend::new().map_err(BenchError::Gpu)?;
    if let Some(p) = args.gpu_projection {
        g.set_projection(p).map_err(BenchError::Gpu)?;
    }
    g.set_rsf_on_gpu(args.rsf_on_gpu).map_err(BenchError::Gpu)?;
    g.set_tests_on_device(!args.tests_on_cpu);
    g.set_keep_sweep_maps(!args.sweep_maps_on_cpu);
    g.set_resident_boxes(!args.boxes_inline);
    g.set_resident_parts(!args.occluders_inline);
    if let Some(n) = args.pixels_per_device_test {
        g.set_pixels_per_device_test(n);
    }
    if let Some(bytes) = args.gpu_sampler_memory {
        g.set_sampler_memory(bytes);
    }
    Ok(g)
}

/// Runs the benchmark and returns its rows (progress lines to [`BenchOptions::progress`]).
///
/// # Errors
/// Bad options, a `pvs_out` folder that cannot be created or written, a shared scene that
/// exists but cannot be loaded, [`BenchBackend::Gpu`] without an adapter, or a backend
/// failure.
pub fn collect(args: &BenchOptions) -> Result<Bench, BenchError> {
    let start = Instant::now();
    let plan = Plan::new(args)?;
    let settings = BakeSettings {
        rsf: args.rsf,
        ..BakeSettings::default()
    };
    let mut skipped = Vec::new();

    let cpu = CpuBackend::new();
    let gpu = match args.backend {
        BenchBackend::Cpu => None,
        BenchBackend::Gpu => Some(gpu_backend(args)?),
        BenchBackend::All => match gpu_backend(args) {
            Ok(g) => Some(g),
            Err(e) => {
                skipped.push(format!("gpu: skipped, {e}"));
                say!(args.progress, "bench: gpu skipped: {e}");
                None
            }
        },
    };
    let mut backends: Vec<(&dyn RasterBackend, usize)> = Vec::new();
    if args.backend != BenchBackend::Gpu {
        backends.push((&cpu, plan.cells));
    }
    if let Some(g) = &gpu {
        backends.push((g, plan.gpu_cells));
    }

    let mut rows = Vec::new();
    for name in SCENES {
        if let Some(list) = &args.scenes
            && !list.iter().any(|s| s == name)
        {
            continue;
        }
        let t = Instant::now();
        say!(args.progress, "bench: {name}: preparing");
        let bs = match build(name, args, &plan)? {
            Ok(s) => s,
            Err(why) => {
                say!(args.progress, "bench: {why}");
                skipped.push(why);
                continue;
            }
        };
        let scene = &bs.scene;
        say!(
            args.progress,
            "bench: {}: {} triangles, {} objects, {} cells ({:.1} s)",
            bs.name,
            scene.triangles.len(),
            scene.objects.len(),
            bs.cells.len(),
            t.elapsed().as_secs_f64()
        );
        if bs.cells.is_empty() {
            let why = format!("{}: skipped, no free cell found", bs.name);
            say!(args.progress, "bench: {why}");
            skipped.push(why);
            continue;
        }
        let run = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            bench_scene(&bs, &backends, &settings, &plan, args)
        }));
        match run {
            Ok(r) => rows.extend(r?),
            Err(panic) => {
                let msg = panic_message(&*panic);
                let why = format!(
                    "{}: FAILED, the bake or validation panicked: {msg}",
                    bs.name
                );
                say!(args.progress, "bench: {why}");
                skipped.push(why);
            }
        }
        say!(
            args.progress,
            "bench: {}: done in {:.1} s",
            bs.name,
            t.elapsed().as_secs_f64()
        );
    }
    Ok(Bench {
        format: "umbrasweep-bench".into(),
        quick: args.quick,
        rays_per_cell: plan.rays,
        cells: plan.cells,
        gpu_cells: plan.gpu_cells,
        seed: args.seed,
        threads: rayon::current_num_threads(),
        rows,
        skipped,
        seconds: start.elapsed().as_secs_f64(),
        hunt_rays: args.hunt_rays,
        confirm_rays: args.confirm_rays,
    })
}

/// Bakes and validates one scene with every backend: one row per backend.
///
/// # Errors
/// A backend failure.
fn bench_scene(
    bs: &BenchScene,
    backends: &[(&dyn RasterBackend, usize)],
    settings: &BakeSettings,
    plan: &Plan,
    args: &BenchOptions,
) -> Result<Vec<BenchRow>, BenchError> {
    let seed = args.seed;
    let scene = &bs.scene;
    let mut out = Vec::new();
    // The rays it may cast: each cell's sample, and each backend's hunt and confirmation.
    let checks = args.hunt_rays.unwrap_or(0) + args.confirm_rays.unwrap_or(0);
    let per_cell = plan.rays + backends.len() as u64 * checks;
    let index = SceneRays::for_rays(scene, bs.cells.len() as u64 * per_cell);
    // Sampled visible set and its time, per cell, shared by the backends.
    let mut samples: Vec<Option<Sampled>> = vec![None; bs.cells.len()];
    for &(backend, max_cells) in backends {
        let cells = &bs.cells[..max_cells.min(bs.cells.len())];
        let t = Instant::now();
        say!(
            args.progress,
            "bench: {}: baking {} cells on {}",
            bs.name,
            cells.len(),
            backend.name()
        );
        let reset = reset_peak();
        let before = backend.counters();
        let result =
            bake(scene, cells, settings, backend, None).map_err(|source| BenchError::Bake {
                scene: bs.name.clone(),
                backend: backend.name().into(),
                source,
            })?;
        let peak = if reset { peak_mib() } else { None };
        let device = backend
            .counters()
            .zip(before)
            .map(|(after, before)| DeviceRow::of(&after.since(&before), cells.len()));
        say!(
            args.progress,
            "bench: {}: baked in {:.1} s; validating with {} rays per cell",
            bs.name,
            t.elapsed().as_secs_f64(),
            plan.rays
        );
        if let Some(dir) = &plan.pvs_out {
            let path = dir.join(format!("{}-{}.json", bs.name, backend.name()));
            let doc = crate::bake::to_document(scene, cells, &result, settings);
            crate::pvs::json::write(&path, &doc).map_err(BenchError::WritePvs)?;
        }
        for (i, cell) in cells.iter().enumerate() {
            if samples[i].is_none() {
                samples[i] = Some(sample(&index, scene, *cell, plan.rays, seed, i));
            }
        }
        let truth: Vec<&Sampled> = samples[..cells.len()].iter().flatten().collect();
        let ids: Vec<usize> = (0..cells.len()).collect();
        let mut row = score(
            &bs.name,
            scene,
            cells,
            &ids,
            &result,
            &truth,
            plan.rays,
            args.progress,
        );
        row.peak_mib = peak;
        row.device = device;
        if row.backend == "gpu" {
            row.gpu_projection = backend.as_gpu().map(|g| g.projection().to_string());
        }
        if args.hunt_rays.is_some() || args.confirm_rays.is_some() {
            let doc = crate::bake::to_document(scene, cells, &result, settings);
            let label = format!("{} [{}]", bs.name, backend.name());
            (row.hunt, row.confirm) = harder_checks(&index, scene, &doc, plan.rays, args, &label);
        }
        out.push(row);
    }
    Ok(out)
}

/// Resets the process's resident high-water mark to the current resident size (Linux);
/// false where that is not possible.
pub(crate) fn reset_peak() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// The process's resident high-water mark (`VmHWM`), MiB.
pub(crate) fn peak_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line
        .trim_start_matches("VmHWM:")
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    Some(kib / 1024.0)
}

/// A cell's ray-sampled visible set and the milliseconds sampling took.
pub(crate) type Sampled = (CellSample, f64);

/// Samples the visible set of `cell`, the scene's cell number `cell_index`, with `rays` rays
/// (the sampler of `umbrasweep validate`, alpha-tested triangles not blocking): the same
/// seed and index give the same rays, so every bake of that cell is checked against the same
/// ground truth.
pub(crate) fn sample(
    index: &SceneRays,
    scene: &Scene,
    cell: Aabb,
    rays: u64,
    seed: u64,
    cell_index: usize,
) -> Sampled {
    let t = Instant::now();
    let s = sample_cell(index, scene, cell, rays, seed, cell_index as u64, false);
    (s, t.elapsed().as_secs_f64() * 1e3)
}

/// Scores one bake of `cells` (scene cell numbers `ids`) against their sampled visible sets
/// `truth`: every false cull is reported to `log` with its witness ray, and the row holds the
/// means over the cells.
#[expect(
    clippy::too_many_arguments,
    reason = "the bake, its cells and their truth, plus the ray count and the progress log"
)]
pub(crate) fn score(
    name: &str,
    scene: &Scene,
    cells: &[Aabb],
    ids: &[usize],
    result: &BakeResult,
    truth: &[&Sampled],
    rays: u64,
    log: Option<ProgressLog>,
) -> BenchRow {
    assert!(cells.len() == result.cells.len() && cells.len() == truth.len());
    let mut reports = Vec::new();
    for (cell, (r, sample)) in cells.iter().zip(result.cells.iter().zip(truth)) {
        let pvs = PvsCell {
            min: cell.min.to_array(),
            max: cell.max.to_array(),
            visible: r.visible.clone(),
            ms: r.ms,
            cullers: Vec::new(),
            parent: None,
        };
        reports.push(cell_report(scene, &pvs, &sample.0));
    }
    let nc = cells.len() as f64;
    let ratios: Vec<f64> = reports.iter().filter_map(|r| r.pvs_over_vs).collect();
    let false_culls = reports.iter().map(|r| r.false_culls.len()).sum();
    for (&i, r) in ids.iter().zip(&reports) {
        for f in &r.false_culls {
            say!(
                log,
                "bench: FALSE CULL {name} [{}] cell {i} {:?}–{:?}: object {} {:?}, ray \
                 origin {:?} direction {:?}",
                result.backend,
                r.min,
                r.max,
                f.object,
                f.name,
                f.origin,
                f.direction
            );
        }
    }
    let ms: Vec<f64> = result.cells.iter().map(|c| c.ms).collect();
    let vms: Vec<f64> = truth.iter().map(|s| s.1).collect();
    BenchRow {
        scene: name.into(),
        triangles: scene.triangles.len(),
        objects: scene.objects.len(),
        cells: cells.len(),
        backend: result.backend.clone(),
        adapter: result.adapter.clone(),
        gpu_projection: None,
        median_ms_per_cell: median(&ms),
        validate_ms_per_cell: median(&vms),
        peak_mib: None,
        device: None,
        objects_culled_percent: reports
            .iter()
            .map(|r| r.objects_culled_percent)
            .sum::<f64>()
            / nc,
        triangles_culled_percent: reports
            .iter()
            .map(|r| r.triangles_culled_percent)
            .sum::<f64>()
            / nc,
        pvs_over_vs: (!ratios.is_empty()).then(|| ratios.iter().sum::<f64>() / ratios.len() as f64),
        false_culls,
        planes_per_cell: result.cells.iter().map(|c| c.planes as f64).sum::<f64>() / nc,
        rays_per_cell: rays,
        culler_ms_per_cell: result
            .cullers
            .iter()
            .enumerate()
            .map(|(k, name)| CullerMs {
                culler: (*name).to_string(),
                median_ms: median(
                    &result
                        .cells
                        .iter()
                        .filter_map(|c| c.cullers.get(k).map(|s| s.ms))
                        .collect::<Vec<_>>(),
                ),
            })
            .collect(),
        hunt: None,
        confirm: None,
    }
}

/// The columns of the harder checks (`--hunt-rays`, `--confirm-rays`).
pub const CHECK_COLUMNS: [&str; 7] = [
    "row",
    "hunted",
    "rays/obj",
    "hunt false culls",
    "VS+",
    "PVS/VS+",
    "confirm false culls",
];

/// Appends the harder checks of `rows` (each with its label), if any row has them: culled
/// objects hunted, the fewest rays any got, the false culls the hunt found, |VS+| (the `VS+`
/// column) and PVS/VS+ (means per cell).
pub(crate) fn checks_table(
    out: &mut String,
    rows: &[(String, &BenchRow)],
    hunt_rays: Option<u64>,
    confirm_rays: Option<u64>,
) {
    let rows: Vec<Vec<String>> = rows
        .iter()
        .filter(|(_, r)| r.hunt.is_some() || r.confirm.is_some())
        .map(|(label, r)| {
            let dash = || "–".to_string();
            let (h, c) = (r.hunt.as_ref(), r.confirm.as_ref());
            vec![
                label.clone(),
                h.map_or_else(dash, |h| h.hunted_objects.to_string()),
                h.map_or_else(dash, |h| h.rays_per_culled_object.to_string()),
                h.map_or_else(dash, |h| h.false_culls.to_string()),
                c.map_or_else(dash, |c| format!("{:.1}", c.vs_plus)),
                c.and_then(|c| c.pvs_over_confirmed_vs)
                    .map_or_else(dash, |v| format!("{v:.2}")),
                c.map_or_else(dash, |c| c.false_culls.to_string()),
            ]
        })
        .collect();
    if rows.is_empty() {
        return;
    }
    let _ = writeln!(
        out,
        "\nharder checks{}{}:\n",
        hunt_rays.map_or(String::new(), |n| format!(", hunt {n} rays per cell")),
        confirm_rays.map_or(String::new(), |n| format!(", confirm {n} rays per cell"))
    );
    let mut left = [false; CHECK_COLUMNS.len()];
    left[0] = true;
    markdown_table(out, &CHECK_COLUMNS, &rows, &left);
}

/// Appends a Markdown table: the header, the alignment row (`left[k]`: column `k` is
/// left-aligned, else right-aligned), then the rows, every column padded to its widest cell.
pub(crate) fn markdown_table(
    out: &mut String,
    header: &[&str],
    rows: &[Vec<String>],
    left: &[bool],
) {
    let mut width: Vec<usize> = header.iter().map(|c| c.chars().count()).collect();
    for row in rows {
        for (w, c) in width.iter_mut().zip(row) {
            *w = (*w).max(c.chars().count());
        }
    }
    let line = |out: &mut String, row: &[String]| {
        out.push('|');
        for (k, (c, w)) in row.iter().zip(&width).enumerate() {
            let pad = w - c.chars().count();
            if left[k] {
                let _ = write!(out, " {c}{} |", " ".repeat(pad));
            } else {
                let _ = write!(out, " {}{c} |", " ".repeat(pad));
            }
        }
        out.push('\n');
    };
    let header: Vec<String> = header.iter().map(|c| c.to_string()).collect();
    line(out, &header);
    out.push('|');
    for (k, w) in width.iter().enumerate() {
        let dashes = "-".repeat(*w);
        if left[k] {
            let _ = write!(out, " {dashes} |");
        } else {
            let _ = write!(out, " {}: |", &dashes[1..]);
        }
    }
    out.push('\n');
    for row in rows {
        line(out, row);
    }
}

/// The columns of the table, in order.
pub const COLUMNS: [&str; 13] = [
    "scene",
    "triangles",
    "objects",
    "cells",
    "backend",
    "median ms/cell",
    "validate ms/cell",
    "% culled",
    "% tris culled",
    "PVS/VS",
    "false culls",
    "planes/cell",
    "peak MiB",
];

/// The columns of the device table (rows of backends with a device).
const DEVICE_COLUMNS: [&str; 9] = [
    "scene",
    "backend",
    "passes",
    "KiB up",
    "KiB read back",
    "maps read back / kept",
    "CPU setup ms",
    "device ms (wall)",
    "GPU pass ms (timestamps)",
];

impl Bench {
    /// The table: a header line, then a Markdown table (one row per scene and backend), then
    /// the adapters and anything skipped.
    pub fn table(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "umbrasweep bench{}: {} cells per scene{}, {} validation rays per cell{}, seed {}, {} \
             threads, {:.0} s",
            if self.quick { " --quick" } else { "" },
            self.cells,
            if self.rows.iter().any(|r| r.backend == "gpu") {
                format!(" (the GPU only the first {})", self.gpu_cells)
            } else {
                String::new()
            },
            self.rays_per_cell,
            if self.rays_per_cell < 1_000_000 {
                " (fewer than the full bench's 1,000,000)"
            } else {
                ""
            },
            self.seed,
            self.threads,
            self.seconds
        );
        out.push('\n');
        let cells: Vec<Vec<String>> = self
            .rows
            .iter()
            .map(|r| {
                vec![
                    r.scene.clone(),
                    r.triangles.to_string(),
                    r.objects.to_string(),
                    r.cells.to_string(),
                    r.backend.clone(),
                    format!("{:.1}", r.median_ms_per_cell),
                    format!("{:.1}", r.validate_ms_per_cell),
                    format!("{:.1}", r.objects_culled_percent),
                    format!("{:.1}", r.triangles_culled_percent),
                    r.pvs_over_vs.map_or("–".into(), |v| format!("{v:.2}")),
                    r.false_culls.to_string(),
                    format!("{:.1}", r.planes_per_cell),
                    r.peak_mib.map_or("n/a".into(), |p| format!("{p:.0}")),
                ]
            })
            .collect();
        let left: Vec<bool> = (0..COLUMNS.len()).map(|k| k == 0 || k == 4).collect();
        markdown_table(&mut out, &COLUMNS, &cells, &left);
        let labelled: Vec<(String, &BenchRow)> = self
            .rows
            .iter()
            .map(|r| (format!("{} [{}]", r.scene, r.backend), r))
            .collect();
        checks_table(&mut out, &labelled, self.hunt_rays, self.confirm_rays);
        let mut adapters: Vec<&str> = self
            .rows
            .iter()
            .filter_map(|r| r.adapter.as_deref())
            .collect();
        adapters.dedup();
        out.push('\n');
        let device: Vec<Vec<String>> = self
            .rows
            .iter()
            .filter_map(|r| r.device.as_ref().map(|d| (r, d)))
            .map(|(r, d)| {
                vec![
                    r.scene.clone(),
                    r.backend.clone(),
                    format!("{:.1}", d.passes_per_cell),
                    format!("{:.0}", d.kib_up_per_cell),
                    format!("{:.0}", d.kib_down_per_cell),
                    format!("{:.1} / {:.1}", d.maps_down_per_cell, d.maps_kept_per_cell),
                    format!("{:.1}", d.setup_ms_per_cell),
                    format!("{:.1}", d.device_ms_per_cell),
                    d.pass_ms_per_cell
                        .map_or("n/a".into(), |p| format!("{p:.2}")),
                ]
            })
            .collect();
        let timed: Vec<Vec<String>> = self
            .rows
            .iter()
            .filter(|r| !r.culler_ms_per_cell.is_empty())
            .map(|r| {
                vec![
                    r.scene.clone(),
                    r.backend.clone(),
                    r.culler_ms_per_cell
                        .iter()
                        .map(|c| format!("{} {:.1}", c.culler, c.median_ms))
                        .collect::<Vec<_>>()
                        .join(", "),
                ]
            })
            .collect();
        if !timed.is_empty() {
            out.push_str("Median ms per cell per culler:\n\n");
            markdown_table(
                &mut out,
                &["scene", "backend", "cullers"],
                &timed,
                &[true, true, true],
            );
            out.push('\n');
        }
        if !device.is_empty() {
            out.push_str("Per cell on the device:\n\n");
            let left: Vec<bool> = (0..DEVICE_COLUMNS.len()).map(|k| k < 2).collect();
            markdown_table(&mut out, &DEVICE_COLUMNS, &device, &left);
            out.push('\n');
        }
        for a in adapters {
            let _ = writeln!(out, "gpu adapter: {a}");
        }
        for s in &self.skipped {
            let _ = writeln!(out, "{s}");
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tiny_bench_prints_every_column() {
        let bench = collect(&BenchOptions {
            quick: true,
            scenes: Some(vec!["boxfield".into(), "city".into()]),
            cells: Some(1),
            rays: Some(1000),
            backend: BenchBackend::Cpu,
            ..BenchOptions::default()
        })
        .unwrap();
        assert_eq!(bench.rows.len(), 2);
        assert!(
            bench
                .rows
                .iter()
                .all(|r| r.cells == 1 && r.backend == "cpu")
        );
        let table = bench.table();
        let header = table.lines().nth(2).unwrap();
        let cols: Vec<&str> = header
            .split('|')
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .collect();
        assert_eq!(cols, COLUMNS);
        let (main, cullers) = table
            .split_once("Median ms per cell per culler:")
            .expect("the culler table");
        assert_eq!(
            main.lines().filter(|l| l.starts_with("| boxfield")).count(),
            1
        );
        // Every row names its pipeline's cullers with a time.
        for r in &bench.rows {
            assert!(!r.culler_ms_per_cell.is_empty(), "{}", r.scene);
            let line = cullers
                .lines()
                .find(|l| l.starts_with(&format!("| {}", r.scene)))
                .unwrap_or_else(|| panic!("no culler line for {}", r.scene));
            for c in &r.culler_ms_per_cell {
                assert!(c.median_ms >= 0.0);
                assert!(line.contains(&c.culler), "{line}");
            }
        }
        let city = bench.rows.iter().find(|r| r.scene == "city").unwrap();
        assert_eq!(
            city.culler_ms_per_cell[0].culler, "ray_space_factorization",
            "the city runs ray space factorization first"
        );
    }

    #[test]
    fn harder_checks_hunt_and_confirm_the_scene_rows() {
        let opts = BenchOptions {
            quick: true,
            scenes: Some(vec!["city".into()]),
            cells: Some(2),
            rays: Some(2000),
            backend: BenchBackend::Cpu,
            hunt_rays: Some(20_000),
            confirm_rays: Some(20_000),
            ..BenchOptions::default()
        };
        let bench = collect(&opts).unwrap();
        let r = &bench.rows[0];
        let h = r.hunt.as_ref().expect("hunted");
        let c = r.confirm.as_ref().expect("confirmed");
        // The hunt's culled objects are the row's (every object of the city has area).
        let culled = r.objects_culled_percent / 100.0 * (r.objects * r.cells) as f64;
        assert!(
            (h.hunted_objects as f64 - culled).abs() < 1e-6,
            "{h:?} {culled}"
        );
        assert!(h.hunted_objects > 0 && h.false_culls == 0, "{h:?}");
        assert!(h.rays_per_culled_object >= 1 && h.rays_per_cell == 20_000);
        // Confirmation only adds visible objects: PVS/VS+ is at least 1 and at most the PVS
        // over the confirmation's own sample (which sees at least one object per cell).
        let pvs = r.objects as f64 * (1.0 - r.objects_culled_percent / 100.0);
        let ratio = c.pvs_over_confirmed_vs.unwrap();
        assert!(ratio >= 1.0 && ratio <= pvs, "{c:?}");
        assert!(c.vs_plus >= 1.0 && c.confirm_rays == 20_000, "{c:?}");
        assert_eq!(c.false_culls, 0, "{c:?}");
        let table = bench.table();
        assert!(
            table.contains("harder checks, hunt 20000 rays per cell, confirm 20000 rays per cell"),
            "{table}"
        );
        assert!(table.contains("| city [cpu]"), "{table}");
        let json = serde_json::to_value(&bench).unwrap();
        assert_eq!(json["hunt_rays"], 20_000);
        assert!(json["rows"][0]["confirm"]["vs_plus"].is_number());
        assert_eq!(json["rows"][0]["confirm"]["false_culls"], 0);
        // Zero is refused.
        let err = collect(&BenchOptions {
            hunt_rays: Some(0),
            ..opts
        })
        .unwrap_err();
        assert!(err.to_string().contains("--hunt-rays"), "{err}");
    }

    #[test]
    fn unknown_scenes_are_refused() {
        let err = collect(&BenchOptions {
            scenes: Some(vec!["moon".into()]),
            ..BenchOptions::default()
        })
        .unwrap_err();
        assert!(matches!(err, BenchError::UnknownScene(_)), "{err:?}");
        assert!(err.to_string().contains("moon"), "{err}");
    }
}
