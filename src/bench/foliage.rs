//! `umbrasweep bench --foliage`: the foliage study (issue 5). This module owns the studies —
//! which forest, which cells and which bake settings make each row — running them on one
//! backend (the CPU unless `--backend gpu`), the peak memory of each bake, and the study's
//! tables and `--json` document. Validation and the table layout are shared with the scene
//! bench (`sample`, `score`, `markdown_table` of [`super`]).
//!
//! The studies, in the order they run and print (each a list of rows, a row being one
//! variant of the bake settings on one forest; all forests generated in memory from `--seed`
//! except the jacaranda's model, read from the shared scene folder):
//!
//! * `coarse`: [`ForestOptions::coarse`] (1,500 trees, leaves ~1.5 across, path cells
//!   1×1×1), `--sweep`, `--no-sweep` and `--sweep --resolution 1024 --sweep-planes 32` (the
//!   cheapest setting measured to reach issue 5's 90 %: [`GOAL_RESOLUTION`]).
//! * `ellipsoid`: the coarse forest with ellipsoid crowns (`gen forest --preset coarse
//!   --crown-shape ellipsoid`, the presets' crowns until November 2026), `--sweep` and
//!   `--no-sweep`: its crowns leave an open band below eye level, so rays see about twice as
//!   many objects.
//! * `fine`: [`ForestOptions::fine`] (leaves ~0.5 across) with 4×2×4 cells (and an 8-unit
//!   path, the least round width such cells fit in, as `gen forest --path-width` would need),
//!   `--sweep`, `--sweep --subcell 2|1|0.5` (on `--foliage-subcell-cells` of the cells, spread
//!   evenly), `--no-sweep` and the shrunk-occluder sampler after the sweep (`--sweep --sampling
//!   --sampling-budget 2000`, on `--foliage-subcell-cells` cells; the coarse study has this row
//!   too).
//! * `params`: the coarse forest with the sweep, one row per single change from the default
//!   settings: kernel spacing with K = 3, 5, 9 (at most 256 planes, so K decides), 12, 24, 48,
//!   96 geometric sweep planes, resolution 128, 512, 1024, extend 1.0, 1.2, 2.0.
//! * `paper`: [`ForestOptions::paper`] (7,750 trees, 7.8 M triangles), `--sweep`, on
//!   `--foliage-paper-cells` cells, and the sampler row (as for `coarse`) on
//!   `--foliage-subcell-cells` of them: its time per cell and peak memory.
//! * `jacaranda`: `foliage/jacaranda_tree.glb` instanced by [`forest_of_models`] as
//!   `gen forest --preset coarse --tree-model` does (the coarse options, the spacing from the
//!   model's footprint, each tree split into 8 objects with `--model-split 8`) but with
//!   `--foliage-model-trees` trees, `--sweep` and `--no-sweep`.
//! * `palm`, `birch`, `beech`: forests of the textured trees of `foliage-textured/`
//!   ([`TEXTURED`]: palm_tree_5, the crooked birch of the low-poly pack, the European beech),
//!   placed like the jacaranda (scaled to a realistic height, each split into 8 objects) and
//!   baked with the sweep four ways: alpha-tested cards ignored (`--alpha-cards ignore`,
//!   the behaviour before issue 21), their conservative coverage over all mip levels (the
//!   default), trusting mip levels 0..4 only (`--alpha-mips 4`), and the unsafe
//!   `--alpha-occluders` (whole cards opaque). Validation traces cards as a renderer at full
//!   resolution draws them (bilinear alpha at mip 0), so the last row's false culls are real.
//!
//! Every cell of a forest is sampled once (the same rays as the scene bench: seed, cell
//! number) before its first bake, and every row baking it is checked against that sample.
//! Peak memory is the process's resident high-water mark (`VmHWM` of `/proc/self/status`)
//! read after each bake, reset (`/proc/self/clear_refs`) just before it: the scene held in
//! memory plus what the bake needs.

use super::{
    BenchBackend, BenchError, BenchOptions, BenchRow, Sampled, markdown_table, panic_message,
    peak_mib, reset_peak, sample, say, score, shared_file, shared_folder,
};
use crate::backend::RasterBackend;
use crate::backend::cpu::CpuBackend;
use crate::bake::{BakeHooks, BakeSettings, SamplerCheckpoints, SweepChoice, bake_cells};
use crate::generate::{CrownShape, ForestOptions, TreeModel, forest, forest_of_models};
use crate::geom::Aabb;
use crate::project::planes::{Placement, Spacing};
use crate::scene::Scene;
use crate::validate::SceneRays;
use glam::Vec3;
use serde::Serialize;
use std::fmt::Write as _;
use std::time::Instant;

/// The studies, in the order they run and print.
pub const STUDIES: [&str; 9] = [
    "coarse",
    "ellipsoid",
    "fine",
    "params",
    "paper",
    "jacaranda",
    "palm",
    "birch",
    "beech",
];

/// The textured-tree studies: (study, model in the shared scene folder, tree height in scene
/// units, trees).
pub const TEXTURED: [(&str, &str, f32, u32); 3] = [
    (
        "palm",
        "foliage-textured/palm_tree_5_nextspring/scene.gltf",
        10.0,
        100,
    ),
    (
        "birch",
        "foliage-textured/low_poly_realistic_trees_pack_v124entkl/scene.gltf",
        12.0,
        200,
    ),
    (
        "beech",
        "foliage-textured/euro_beech_fadiyasotodeh_partial/scene.gltf",
        15.0,
        200,
    ),
];

/// Mip levels the `--alpha-mips` row of the textured studies trusts.
pub const TEXTURED_MIPS: u32 = 4;
/// Cells per forest unless `--cells`.
pub const DEFAULT_CELLS: usize = 10;
/// Validation rays per cell unless `--rays` (fewer than the scene bench's 1,000,000: the
/// forests have up to 8 M triangles and every row is validated).
pub const DEFAULT_RAYS: u64 = 200_000;
/// Cells of the sub-cell variants unless `--foliage-subcell-cells`.
pub const DEFAULT_SUBCELL_CELLS: usize = 3;
/// Cells of the paper's forest unless `--foliage-paper-cells`.
pub const DEFAULT_PAPER_CELLS: usize = 5;
/// Jacaranda trees unless `--foliage-model-trees`: 150 × 55 k ≈ 8.2 M triangles, about the
/// paper's forest (gen's coarse 1,500 would make 82 M).
pub const DEFAULT_MODEL_TREES: u32 = 150;
/// Objects per jacaranda tree (`--model-split`): angular sectors around its trunk.
pub const JACARANDA_SPLIT: u32 = 8;

/// The jacaranda model in the shared scene folder.
pub const JACARANDA: &str = "foliage/jacaranda_tree.glb";

/// Cells of the fine study.
const FINE_CELL: Vec3 = Vec3::new(4.0, 2.0, 4.0);
/// Path width of the fine study: 4×2×4 cells need at least 2 × (half their diagonal, 2.83,
/// plus the 1-unit clearance) = 7.66 (the coarse preset's 4 is for 1×1×1 cells).
const FINE_PATH_WIDTH: f32 = 8.0;

/// The forests the studies bake.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Forest {
    Coarse,
    CoarseEllipsoid,
    Fine,
    Paper,
    Jacaranda,
    /// A forest of [`TEXTURED`]`[i]`.
    Textured(usize),
}

impl Forest {
    fn of(study: &str) -> Forest {
        if let Some(i) = TEXTURED.iter().position(|t| t.0 == study) {
            return Forest::Textured(i);
        }
        match study {
            "ellipsoid" => Forest::CoarseEllipsoid,
            "fine" => Forest::Fine,
            "paper" => Forest::Paper,
            "jacaranda" => Forest::Jacaranda,
            _ => Forest::Coarse,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Forest::Coarse => "coarse_forest",
            Forest::CoarseEllipsoid => "coarse_forest_ellipsoid",
            Forest::Fine => "fine_forest",
            Forest::Paper => "paper_forest",
            Forest::Jacaranda => "jacaranda_forest",
            Forest::Textured(0) => "palm_forest",
            Forest::Textured(1) => "birch_forest",
            Forest::Textured(_) => "beech_forest",
        }
    }
}

/// One row of a study before it runs.
#[derive(Clone, Debug, PartialEq)]
pub struct Variant {
    /// The `umbrasweep bake` flags giving these settings (e.g. `--sweep --subcell 2`).
    pub label: String,
    /// The bake settings.
    pub settings: BakeSettings,
    /// Bake only this many of the forest's cells, spread evenly (the sub-cell variants).
    pub max_cells: Option<usize>,
}

fn variant(label: impl Into<String>, settings: BakeSettings) -> Variant {
    Variant {
        label: label.into(),
        settings,
        max_cells: None,
    }
}

/// The finer sweep of the coarse study's third row: the cheapest setting measured to cull at
/// least 90 % of the coarse forest (issue 5's goal; 90.2 % at about 3 s per cell, against
/// 86.7 % at about 0.45 s with the defaults). Resolution 1024 alone gave 89.7 %, 48 planes
/// alone 87.0 %, both 90.4 % at twice the time of 32 planes.
pub const GOAL_RESOLUTION: u32 = 1024;
/// See [`GOAL_RESOLUTION`].
pub const GOAL_SWEEP_PLANES: u32 = 32;

/// The default settings with the sweep on (`On`) or off (`Off`).
fn swept(sweep: SweepChoice) -> BakeSettings {
    BakeSettings {
        sweep,
        ..BakeSettings::default()
    }
}

/// Sample points per cell of the sampler rows (`sampled`): about ten minutes per cell on two
/// cores.
pub const SAMPLING_BENCH_POINTS: u64 = 2000;

/// The sampler row of a study: the sweep, then the shrunk-occluder sampler with at most
/// [`SAMPLING_BENCH_POINTS`] points per cell, on `cells` cells ([`with_sampler`] sets the
/// budget and `--sampling-max-eps` the run asks for).
fn sampled(cells: usize) -> Variant {
    let mut s = swept(SweepChoice::On);
    s.sampling = SweepChoice::On;
    s.sampling_settings.budget_points = SAMPLING_BENCH_POINTS;
    Variant {
        label: format!("--sweep --sampling --sampling-budget {SAMPLING_BENCH_POINTS}"),
        settings: s,
        max_cells: Some(cells),
    }
}

/// What a run asks of the foliage study's sampler rows (`--foliage-sampling-…`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SamplerRow {
    /// Sample points per cell (`--sampling-budget`).
    pub budget: u64,
    /// `--sampling-max-eps`: levels coarser than this are split without sampling.
    pub max_eps: Option<f64>,
    /// The tuck pass (`--sampling-tuck`).
    pub tuck: bool,
    /// The finest ε (`--sampling-eps`; `None`: the bake's default from the leaves' size).
    pub eps: Option<f64>,
    /// Refinement levels (`--sampling-levels`; `None`: the bake's default).
    pub levels: Option<u32>,
}

impl Default for SamplerRow {
    fn default() -> Self {
        SamplerRow {
            budget: SAMPLING_BENCH_POINTS,
            max_eps: None,
            tuck: false,
            eps: None,
            levels: None,
        }
    }
}

/// `list` with its sampler rows ([`variants`]) set as `row` asks, their labels saying so.
pub fn with_sampler(mut list: Vec<Variant>, row: &SamplerRow) -> Vec<Variant> {
    for v in &mut list {
        if v.settings.sampling != SweepChoice::On {
            continue;
        }
        let sa = &mut v.settings.sampling_settings;
        sa.budget_points = row.budget;
        sa.max_eps = row.max_eps;
        sa.tuck = row.tuck;
        v.label = format!("--sweep --sampling --sampling-budget {}", row.budget);
        if let Some(e) = row.eps {
            sa.eps = Some(e);
            v.label += &format!(" --sampling-eps {e}");
        }
        if let Some(n) = row.levels {
            sa.levels = n;
            v.label += &format!(" --sampling-levels {n}");
        }
        if let Some(e) = row.max_eps {
            v.label += &format!(" --sampling-max-eps {e}");
        }
        if row.tuck {
            v.label += " --sampling-tuck";
        }
    }
    list
}

/// The rows of `study` (one of [`STUDIES`]); the sub-cell and sampler variants bake
/// `subcell_cells` cells.
pub fn variants(study: &str, subcell_cells: usize) -> Vec<Variant> {
    let on = || swept(SweepChoice::On);
    let off = || swept(SweepChoice::Off);
    match study {
        "coarse" => {
            let mut fine_grained = on();
            fine_grained.resolution = GOAL_RESOLUTION;
            fine_grained.sweep_settings.planes = GOAL_SWEEP_PLANES;
            vec![
                variant("--sweep", on()),
                variant("--no-sweep", off()),
                variant(
                    format!(
                        "--sweep --resolution {GOAL_RESOLUTION} --sweep-planes {GOAL_SWEEP_PLANES}"
                    ),
                    fine_grained,
                ),
                sampled(subcell_cells),
            ]
        }
        "ellipsoid" | "jacaranda" => {
            vec![variant("--sweep", on()), variant("--no-sweep", off())]
        }
        "palm" | "birch" | "beech" => {
            use crate::settings::AlphaCards;
            vec![
                variant(
                    "--sweep --alpha-cards ignore",
                    BakeSettings {
                        alpha_cards: AlphaCards::Ignore,
                        ..on()
                    },
                ),
                variant("--sweep", on()),
                variant(
                    format!("--sweep --alpha-mips {TEXTURED_MIPS}"),
                    BakeSettings {
                        alpha_mips: TEXTURED_MIPS,
                        ..on()
                    },
                ),
                variant(
                    "--sweep --alpha-occluders",
                    BakeSettings {
                        alpha_occluders: true,
                        ..on()
                    },
                ),
            ]
        }
        "fine" => {
            let mut v = vec![variant("--sweep", on())];
            for s in [2.0, 1.0, 0.5] {
                v.push(Variant {
                    label: format!("--sweep --subcell {s}"),
                    settings: BakeSettings {
                        subcell: Some(s),
                        ..on()
                    },
                    max_cells: Some(subcell_cells),
                });
            }
            v.push(variant("--no-sweep", off()));
            v.push(sampled(subcell_cells));
            v
        }
        "params" => {
            let mut v = Vec::new();
            let mut s = on();
            for k in [3, 5, 9] {
                s.sweep_settings.spacing = Spacing::Kernel;
                s.sweep_settings.kernel = k;
                s.sweep_settings.planes = 256;
                v.push(variant(
                    format!("--sweep --sweep-spacing kernel --kernel {k} --sweep-planes 256"),
                    s.clone(),
                ));
            }
            for n in [12, 24, 48, 96] {
                let mut s = on();
                s.sweep_settings.planes = n;
                v.push(variant(format!("--sweep --sweep-planes {n}"), s));
            }
            for r in [128, 512, 1024] {
                v.push(variant(
                    format!("--sweep --resolution {r}"),
                    BakeSettings {
                        resolution: r,
                        ..on()
                    },
                ));
            }
            for e in [1.0, 1.2, 2.0] {
                v.push(variant(
                    format!("--sweep --extend {e:.1}"),
                    BakeSettings { extend: e, ..on() },
                ));
            }
            for m in [1, 8] {
                v.push(variant(
                    format!("--sweep --max-stretch {m}"),
                    BakeSettings {
                        max_stretch: m,
                        ..on()
                    },
                ));
            }
            v
        }
        "paper" => vec![variant("--sweep", on()), sampled(subcell_cells)],
        _ => Vec::new(),
    }
}

/// The table's short form of a row's settings: what the bake used (e.g. `sweep ≤24
/// geometric, res 256, extend 1.5`).
pub fn describe(s: &BakeSettings) -> String {
    let sw = &s.sweep_settings;
    let mut out = if s.sweep == SweepChoice::On {
        match sw.spacing {
            Spacing::Kernel => format!("sweep ≤{} kernel K={}", sw.planes, sw.kernel),
            Spacing::Geometric => format!("sweep ≤{} geometric", sw.planes),
        }
    } else {
        let placement = match s.placement {
            Placement::Geometric => "geometric",
            Placement::Quantile => "quantile",
        };
        format!("{}+{} planes {placement}", s.planes, s.slice_planes)
    };
    let _ = write!(out, ", res {}, extend {:.1}", s.resolution, s.extend);
    if s.max_stretch != BakeSettings::default_settings().max_stretch {
        let _ = write!(out, ", stretch ≤{}", s.max_stretch);
    }
    if let Some(x) = s.subcell {
        let _ = write!(out, ", subcell {x}");
    }
    if s.sampling == SweepChoice::On {
        let sa = &s.sampling_settings;
        let _ = write!(
            out,
            ", sampling ε {}, ≤{} points",
            sa.eps.map_or("auto".to_string(), |e| e.to_string()),
            sa.budget_points
        );
        if sa.levels != BakeSettings::default_settings().sampling_settings.levels {
            let _ = write!(out, ", {} levels", sa.levels);
        }
        if let Some(e) = sa.max_eps {
            let _ = write!(out, ", levels ε ≤{e}");
        }
        if sa.tuck {
            out.push_str(", tuck pass");
        }
    }
    out
}

/// One row of the foliage study: a [`BenchRow`] (its fields flattened into the JSON row)
/// with the study, the variant and the bake's peak memory.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FoliageRow {
    /// The study (`coarse`, `fine`, `params`, `paper`, `jacaranda`).
    pub study: String,
    /// The `umbrasweep bake` flags of the variant (e.g. `--sweep --subcell 2`).
    pub variant: String,
    /// The settings the bake used (in the PVS document's form: `"sweep": true`, …).
    pub settings: BakeSettings,
    /// Scene, sizes, cells, times, culling, false culls, planes (see [`BenchRow`]).
    #[serde(flatten)]
    pub row: BenchRow,
    /// The process's peak resident memory during the bake, MiB (`VmHWM`, reset before the
    /// bake); `None` where `/proc/self/status` is unavailable.
    pub peak_mib: Option<f64>,
    /// The sampler's cost curve (rows with the sampler; empty otherwise): per level it ran,
    /// what a budget that ran out right after that level gives, mean per cell.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub sampling_curve: Vec<CurvePoint>,
}

/// One point of a sampler row's cost curve: the state at the end of one level (all levels
/// so far), mean per cell over the row's cells ([`crate::pvs::PvsLevelSummary`] with the
/// share of objects culled).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CurvePoint {
    /// The level's ε (the largest half diagonal of its sample rectangles, any cell).
    pub eps: f64,
    /// Pixels across each 90° view at this level (the largest of the cells).
    pub resolution: u32,
    /// Sample points rendered so far.
    pub points: f64,
    /// Seconds of sampling so far.
    pub seconds: f64,
    /// Objects the sampler had proved hidden so far.
    pub sampler_hidden: f64,
    /// Objects culled by all cullers had the sampler stopped after this level, % (the row's
    /// `objects_culled_percent` less what later levels hid).
    pub objects_culled_percent: f64,
    /// The share of the cells where only the level's probe was sampled.
    pub probe_only: f64,
}

/// The cost curve of a bake's sampler ([`FoliageRow::sampling_curve`]): its levels from the
/// culler summary, each with the % culled that stopping there gives (`culled_percent` is the
/// whole bake's, of `objects` objects). Empty when the sampler did not run.
fn cost_curve(
    result: &crate::bake::BakeResult,
    objects: usize,
    culled_percent: f64,
) -> Vec<CurvePoint> {
    let summary = crate::bake::culler_summary(result);
    let Some(s) = summary
        .iter()
        .find(|c| c.name == crate::bake::SamplingCuller::NAME)
    else {
        return Vec::new();
    };
    let last = s.levels.last().map_or(0.0, |l| l.hidden);
    s.levels
        .iter()
        .map(|l| CurvePoint {
            eps: l.eps,
            resolution: l.resolution,
            points: l.points,
            seconds: l.seconds,
            sampler_hidden: l.hidden,
            objects_culled_percent: culled_percent
                - 100.0 * (last - l.hidden) / objects.max(1) as f64,
            probe_only: l.probe_only,
        })
        .collect()
}

/// `--hunt-rays` and `--confirm-rays`: checks the PVS documents `docs` of a study's rows
/// ([`super::harder_checks`]; one ray index, built after the study's bakes so that it does not
/// add to their peak memory) and fills in the rows' `hunt` and `confirm`.
fn check_rows(
    plan: &Plan,
    args: &BenchOptions,
    study: &str,
    scene: &crate::scene::Scene,
    rows: &mut [FoliageRow],
    docs: &[(usize, crate::pvs::PvsDocument)],
) {
    let checks = args.hunt_rays.unwrap_or(0) + args.confirm_rays.unwrap_or(0);
    let cells: u64 = docs.iter().map(|(_, d)| d.cells.len() as u64).sum();
    let index = SceneRays::for_rays(scene, cells * checks);
    for (k, doc) in docs {
        let row = &mut rows[*k];
        let label = format!("foliage {study} [{}]", row.variant);
        (row.row.hunt, row.row.confirm) =
            super::harder_checks(&index, scene, doc, plan.rays, args, &label);
    }
}

/// One study's heading: what its forest is.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StudyScene {
    /// The study.
    pub study: String,
    /// The forest and its cells, in words.
    pub scene: String,
}

/// A whole `--foliage` run: the `--json` document.
#[derive(Clone, Debug, Serialize)]
pub struct FoliageBench {
    /// `"umbrasweep-bench-foliage"`.
    pub format: String,
    /// The studies run, in order.
    pub studies: Vec<String>,
    /// `cpu` or `gpu`.
    pub backend: String,
    /// The GPU adapter, if any.
    pub adapter: Option<String>,
    /// Validation rays per cell.
    pub rays_per_cell: u64,
    /// Cells per forest (fewer when a path has fewer).
    pub cells: usize,
    /// Cells of the sub-cell variants.
    pub subcell_cells: usize,
    /// Cells of the paper's forest.
    pub paper_cells: usize,
    /// Trees of the jacaranda forest.
    pub model_trees: u32,
    /// Sample points per cell of the sampler rows (`--foliage-sampling-budget`).
    pub sampling_budget_points: u64,
    /// The sampler rows' `--sampling-max-eps`, if given (`--foliage-sampling-max-eps`).
    pub sampling_max_eps: Option<f64>,
    /// Whether the sampler rows ran the tuck pass (`--foliage-sampling-tuck`).
    pub sampling_tuck: bool,
    /// The sampler rows' finest ε, if given (`--foliage-sampling-eps`).
    pub sampling_eps: Option<f64>,
    /// The sampler rows' refinement levels, if given (`--foliage-sampling-levels`).
    pub sampling_levels: Option<u32>,
    /// Hunting rays per cell of every row, if given (`--hunt-rays`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hunt_rays: Option<u64>,
    /// Confirming rays per cell of every row, if given (`--confirm-rays`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub confirm_rays: Option<u64>,
    /// The test-only tree count of the procedural forests, if given.
    pub trees_override: Option<u32>,
    /// Seed of forests and rays.
    pub seed: u64,
    /// Worker threads (rayon).
    pub threads: usize,
    /// Each study's forest, in words.
    pub scenes: Vec<StudyScene>,
    /// One row per study and variant.
    pub rows: Vec<FoliageRow>,
    /// Studies or rows skipped or failed, and why; notes on the peak memory.
    pub skipped: Vec<String>,
    /// Wall-clock time of the whole run, seconds.
    pub seconds: f64,
}

/// Settings after defaults.
struct Plan {
    studies: Vec<&'static str>,
    cells: usize,
    rays: u64,
    subcell_cells: usize,
    paper_cells: usize,
    model_trees: u32,
    sampler: SamplerRow,
    hunt_rays: Option<u64>,
    confirm_rays: Option<u64>,
}

impl Plan {
    fn new(args: &BenchOptions) -> Result<Plan, BenchError> {
        let studies = match &args.foliage_studies {
            None => STUDIES.to_vec(),
            Some(list) => {
                if let Some(bad) = list.iter().find(|s| !STUDIES.contains(&s.as_str())) {
                    return Err(BenchError::UnknownStudy(bad.clone()));
                }
                STUDIES
                    .into_iter()
                    .filter(|s| list.iter().any(|l| l == s))
                    .collect()
            }
        };
        let plan = Plan {
            studies,
            cells: args.cells.unwrap_or(DEFAULT_CELLS),
            rays: args.rays.unwrap_or(DEFAULT_RAYS),
            subcell_cells: args.foliage_subcell_cells,
            paper_cells: args.foliage_paper_cells,
            model_trees: args.foliage_model_trees,
            sampler: SamplerRow {
                budget: args.foliage_sampling_budget,
                max_eps: args.foliage_sampling_max_eps,
                tuck: args.foliage_sampling_tuck,
                eps: args.foliage_sampling_eps,
                levels: args.foliage_sampling_levels,
            },
            hunt_rays: args.hunt_rays,
            confirm_rays: args.confirm_rays,
        };
        let counts = [
            ("--cells", plan.cells as u64),
            ("--rays", plan.rays),
            ("--foliage-subcell-cells", plan.subcell_cells as u64),
            ("--foliage-paper-cells", plan.paper_cells as u64),
            ("--foliage-model-trees", plan.model_trees as u64),
            ("--foliage-trees", args.foliage_trees.unwrap_or(1) as u64),
            ("--foliage-sampling-budget", plan.sampler.budget),
            ("--hunt-rays", plan.hunt_rays.unwrap_or(1)),
            ("--confirm-rays", plan.confirm_rays.unwrap_or(1)),
        ];
        if let Some((flag, _)) = counts.iter().find(|c| c.1 == 0) {
            return Err(BenchError::Zero(flag));
        }
        for (flag, e) in [
            ("--foliage-sampling-max-eps", plan.sampler.max_eps),
            ("--foliage-sampling-eps", plan.sampler.eps),
        ] {
            if let Some(e) = e
                && !(e.is_finite() && e > 0.0)
            {
                return Err(BenchError::BadValue {
                    flag,
                    value: e.to_string(),
                    why: "must be a positive distance in scene units (e.g. 0.05 on the fine \
                          forest)",
                });
            }
        }
        if !(args.checkpoint_seconds >= 0.0 && args.checkpoint_seconds.is_finite()) {
            return Err(BenchError::BadValue {
                flag: "--checkpoint-every",
                value: args.checkpoint_seconds.to_string(),
                why: "must be a number of seconds, 0 or more (0: after every chunk)",
            });
        }
        if let Some(n) = plan.sampler.levels
            && n > crate::settings::SamplingSettings::MAX_LEVELS
        {
            return Err(BenchError::BadValue {
                flag: "--foliage-sampling-levels",
                value: n.to_string(),
                why: "must be between 0 and 12 (each level halves ε and costs about 4× the \
                      points)",
            });
        }
        Ok(plan)
    }
}

/// Runs `work` (a row's bake), reporting the sample points rendered and the face rectangles
/// done so far every minute while it lasts (sampler rows take hours on the fine forest).
fn with_ticker<T>(
    args: &BenchOptions,
    progress: &crate::bake::SamplerProgress,
    study: &str,
    label: &str,
    work: impl FnOnce() -> T,
) -> T {
    let Some(log) = args.progress else {
        return work();
    };
    let t = Instant::now();
    let (stop, wait) = std::sync::mpsc::channel::<()>();
    std::thread::scope(|s| {
        s.spawn(move || {
            let mut pace = crate::bake::RectPace::default();
            let mut note = || {
                use std::sync::atomic::Ordering::Relaxed;
                let rects = (
                    progress.rects_done.load(Relaxed),
                    progress.rects_begun.load(Relaxed),
                );
                let points = progress.points.load(Relaxed);
                (points, rects, pace.update(Instant::now(), points, rects))
            };
            note();
            while let Err(std::sync::mpsc::RecvTimeoutError::Timeout) =
                wait.recv_timeout(std::time::Duration::from_secs(60))
            {
                let (n, (done, begun), left) = note();
                if n > 0 {
                    log(&format!(
                        "bench: foliage {study} [{label}]: {n} sample points so far, {done} of \
                         {begun} rectangles{} ({:.0} s)",
                        left.map_or(String::new(), |d| format!(
                            ", about {:.0} s more at this pace",
                            d.as_secs_f64()
                        )),
                        t.elapsed().as_secs_f64()
                    ));
                }
            }
        });
        let out = work();
        drop(stop);
        out
    })
}

/// A forest ready to bake, with the sampled visible sets of its cells (filled on demand).
struct ForestScene {
    which: Forest,
    scene: Scene,
    cells: Vec<Aabb>,
    truth: Vec<Option<Sampled>>,
    about: String,
}

/// Generates forest `which`; `Ok(Err(reason))` when it needs a shared file that is absent.
fn build(
    which: Forest,
    args: &BenchOptions,
    plan: &Plan,
) -> Result<Result<ForestScene, String>, BenchError> {
    let trees = |n: u32| args.foliage_trees.unwrap_or(n);
    let seed = args.seed;
    let cells = Some(plan.cells);
    let (g, about) = match which {
        Forest::Coarse | Forest::CoarseEllipsoid | Forest::Fine | Forest::Paper => {
            let base = match which {
                Forest::Coarse => ForestOptions::coarse(),
                Forest::CoarseEllipsoid => ForestOptions {
                    crown_shape: CrownShape::Ellipsoid,
                    ..ForestOptions::coarse()
                },
                Forest::Fine => ForestOptions {
                    cell_size: FINE_CELL,
                    path_width: FINE_PATH_WIDTH,
                    ..ForestOptions::fine()
                },
                _ => ForestOptions::paper(),
            };
            let o = ForestOptions {
                seed,
                trees: trees(base.trees),
                max_cells: if which == Forest::Paper {
                    Some(plan.paper_cells)
                } else {
                    cells
                },
                ..base
            };
            let preset = match which {
                Forest::Coarse | Forest::CoarseEllipsoid => "coarse",
                Forest::Fine => "fine",
                _ => "paper",
            };
            let c = o.cell_size;
            let about = format!(
                "`ForestOptions::{preset}()`: {} trees × {} leaves {}–{} across in {} crowns; cells \
                 {}×{}×{} on the path{}",
                o.trees,
                o.leaves,
                o.leaf_size[0],
                o.leaf_size[1],
                match o.crown_shape {
                    CrownShape::Cylinder => "cylinder",
                    CrownShape::Ellipsoid => "ellipsoid",
                },
                c.x,
                c.y,
                c.z,
                if o.path_width != ForestOptions::coarse().path_width {
                    format!(" (path width {})", o.path_width)
                } else {
                    String::new()
                }
            );
            (forest(&o)?, about)
        }
        Forest::Jacaranda => {
            let model = match shared_model(args, "jacaranda", JACARANDA)? {
                Ok(m) => m,
                Err(why) => return Ok(Err(why)),
            };
            // `gen forest --preset coarse --tree-model FILE --trees N --model-split 8`: one
            // object per tree would leave nothing to cull (every tree is seen from every cell),
            // so each tree is 8 objects, like the procedural crowns' sectors.
            let o = ForestOptions {
                seed,
                trees: plan.model_trees,
                area_per_tree: None,
                max_cells: cells,
                model_split: JACARANDA_SPLIT,
                ..ForestOptions::coarse()
            };
            let about = format!(
                "{} instances of `{JACARANDA}` ({} triangles each, scale 1 ± {}, each split into \
                 {} objects around its trunk), as `gen forest --preset coarse --tree-model \
                 --model-split {}` places them (spacing from the model's footprint); cells 1×1×1 \
                 on the path",
                o.trees,
                model.triangles.len(),
                o.scale_jitter,
                o.model_split,
                o.model_split
            );
            (forest_of_models(&o, &model)?, about)
        }
        Forest::Textured(i) => {
            let (study, file, height, trees) = TEXTURED[i];
            let model = match shared_model(args, study, file)? {
                Ok(m) => m,
                Err(why) => return Ok(Err(why)),
            };
            let o = ForestOptions {
                seed,
                trees,
                area_per_tree: None,
                max_cells: cells,
                model_split: JACARANDA_SPLIT,
                model_height: Some(height),
                ..ForestOptions::coarse()
            };
            let about = format!(
                "{} instances of `{file}` ({} triangles each, {} alpha-tested; {height} tall, \
                 scale 1 ± {}, each split into {} objects around its trunk), as `gen forest \
                 --preset coarse --tree-model --model-height {height} --model-split {}` places \
                 them; cells 1×1×1 on the path",
                o.trees,
                model.triangles.len(),
                model.cards.as_ref().map_or(0, |c| c.cards.len()),
                o.scale_jitter,
                o.model_split,
                o.model_split
            );
            (forest_of_models(&o, &model)?, about)
        }
    };
    let scene = g.to_scene(which.name());
    let n = g.cells.len();
    Ok(Ok(ForestScene {
        which,
        scene,
        cells: g.cells,
        truth: vec![None; n],
        about,
    }))
}

/// The tree model `file` of the shared scene folder for `study`; `Ok(Err(reason))` when the
/// folder or the file is absent.
fn shared_model(
    args: &BenchOptions,
    study: &str,
    file: &str,
) -> Result<Result<TreeModel, String>, BenchError> {
    let shared = shared_folder(args)?;
    let path = match shared_file(shared.as_deref(), study, file) {
        Ok(p) => p,
        Err(why) => return Ok(Err(why)),
    };
    let scene = crate::scene::load(&path).map_err(|source| BenchError::Scene {
        path: path.clone(),
        source,
    })?;
    Ok(Ok(TreeModel::from_scene(&scene)))
}

/// The indices of `n` of `len` items spread evenly (all of them when `n >= len`), as the
/// generators keep cells.
fn spread(len: usize, n: Option<usize>) -> Vec<usize> {
    match n {
        Some(n) if n < len => (0..n).map(|i| (2 * i + 1) * len / (2 * n)).collect(),
        _ => (0..len).collect(),
    }
}

/// Runs the foliage study and returns its rows (progress lines to
/// [`BenchOptions::progress`]). A row whose bake fails
/// or panics is reported in `skipped` and the study goes on.
///
/// # Errors
/// Bad options, `--backend gpu` without an adapter, a forest that cannot be generated, or a
/// jacaranda model that exists but cannot be loaded.
pub fn collect(args: &BenchOptions) -> Result<FoliageBench, BenchError> {
    let start = Instant::now();
    let plan = Plan::new(args)?;
    if let Some(dir) = &args.checkpoint_dir {
        std::fs::create_dir_all(dir).map_err(|source| BenchError::CheckpointDir {
            path: dir.clone(),
            source,
        })?;
    }
    let cpu;
    let gpu;
    let backend: &dyn RasterBackend = if args.backend == BenchBackend::Gpu {
        gpu = super::gpu_backend(args)?;
        &gpu
    } else {
        cpu = CpuBackend::new();
        &cpu
    };
    let mut skipped = Vec::new();
    let mut rows = Vec::new();
    let mut scenes = Vec::new();
    let mut peak_reset = true;
    let mut forests: Vec<ForestScene> = Vec::new();
    // The PVS documents of a study's rows awaiting the harder checks: (row, document).
    let mut docs: Vec<(usize, crate::pvs::PvsDocument)> = Vec::new();
    for (k, &study) in plan.studies.iter().enumerate() {
        let which = Forest::of(study);
        // Keep only the forests a study still to come uses (the coarse one for `params`),
        // so that one forest's memory does not add to the next one's peak.
        forests.retain(|f| plan.studies[k..].iter().any(|s| Forest::of(s) == f.which));
        if !forests.iter().any(|f| f.which == which) {
            let t = Instant::now();
            say!(
                args.progress,
                "bench: foliage {study}: generating {}",
                which.name()
            );
            match build(which, args, &plan)? {
                Ok(f) => {
                    say!(
                        args.progress,
                        "bench: foliage {study}: {}: {} triangles, {} objects, {} cells ({:.1} s)",
                        which.name(),
                        f.scene.triangles.len(),
                        f.scene.objects.len(),
                        f.cells.len(),
                        t.elapsed().as_secs_f64()
                    );
                    forests.push(f);
                }
                Err(why) => {
                    say!(args.progress, "bench: {why}");
                    skipped.push(why);
                    continue;
                }
            }
        }
        let f = forests
            .iter_mut()
            .find(|f| f.which == which)
            .expect("built");
        scenes.push(StudyScene {
            study: study.into(),
            scene: f.about.clone(),
        });
        if f.cells.is_empty() {
            let why = format!("{study}: skipped, no cell on the path of {}", which.name());
            say!(args.progress, "bench: {why}");
            skipped.push(why);
            continue;
        }
        let list = with_sampler(variants(study, plan.subcell_cells), &plan.sampler);
        // Sample every cell a row bakes before the first bake, so that the ray index is not
        // held during the bakes (their peak memory).
        let mut ids: Vec<usize> = list
            .iter()
            .flat_map(|v| spread(f.cells.len(), v.max_cells))
            .filter(|&i| f.truth[i].is_none())
            .collect();
        ids.sort_unstable();
        ids.dedup();
        if !ids.is_empty() {
            let t = Instant::now();
            say!(
                args.progress,
                "bench: foliage {study}: sampling {} cells with {} rays each",
                ids.len(),
                plan.rays
            );
            let index = SceneRays::for_rays(&f.scene, ids.len() as u64 * plan.rays);
            for i in ids {
                f.truth[i] = Some(sample(
                    &index, &f.scene, f.cells[i], plan.rays, args.seed, i,
                ));
            }
            say!(
                args.progress,
                "bench: foliage {study}: sampled in {:.1} s",
                t.elapsed().as_secs_f64()
            );
        }
        for (j, v) in list.iter().enumerate() {
            let t = Instant::now();
            let ids = spread(f.cells.len(), v.max_cells);
            let cells: Vec<Aabb> = ids.iter().map(|&i| f.cells[i]).collect();
            // The row's sampler checkpoints (`--checkpoint-dir`), tied to its scene, cells,
            // settings and backend.
            let checkpoints = args.checkpoint_dir.as_ref().map(|dir| {
                let inputs = crate::bake::inputs_hash(
                    &f.scene,
                    &cells,
                    &v.settings,
                    &format!("bench {study} {} backend {}", v.label, backend.name()),
                );
                SamplerCheckpoints::new(
                    &dir.join(format!("{study}-{j:02}")),
                    &inputs,
                    true,
                    args.checkpoint_seconds,
                )
                .kept()
            });
            let truth: Vec<&Sampled> = ids
                .iter()
                .map(|&i| f.truth[i].as_ref().expect("sampled"))
                .collect();
            peak_reset &= reset_peak();
            let run = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                let progress = crate::bake::SamplerProgress::default();
                let all: Vec<usize> = (0..cells.len()).collect();
                let hooks = BakeHooks {
                    sampler_progress: Some(&progress),
                    sampler_checkpoints: checkpoints.as_ref(),
                    ..BakeHooks::default()
                };
                let before = backend.counters();
                let result = with_ticker(args, &progress, study, &v.label, || {
                    bake_cells(&f.scene, &cells, &all, &v.settings, backend, hooks)
                });
                let device = backend.counters().zip(before).map(|(after, before)| {
                    super::DeviceRow::of(&after.since(&before), cells.len())
                });
                if let Some(c) = &checkpoints {
                    let n = c.replayed.load(std::sync::atomic::Ordering::Relaxed);
                    if n > 0 {
                        say!(
                            args.progress,
                            "bench: foliage {study} [{}]: replayed {n} sampler rectangles from \
                             {}.sampler-*",
                            v.label,
                            c.base.display()
                        );
                    }
                }
                let peak = peak_mib();
                result.map(|r| {
                    let mut row = score(
                        which.name(),
                        &f.scene,
                        &cells,
                        &ids,
                        &r,
                        &truth,
                        plan.rays,
                        args.progress,
                    );
                    if row.backend == "gpu" {
                        row.gpu_projection = backend.as_gpu().map(|g| g.projection().to_string());
                    }
                    row.device = device;
                    let curve = cost_curve(&r, f.scene.objects.len(), row.objects_culled_percent);
                    // The PVS document the harder checks read, if any is asked for.
                    let doc = (plan.hunt_rays.is_some() || plan.confirm_rays.is_some())
                        .then(|| crate::bake::to_document(&f.scene, &cells, &r, &v.settings));
                    (row, peak, curve, doc)
                })
            }));
            let (row, peak, sampling_curve, doc) = match run {
                Ok(Ok(r)) => r,
                Ok(Err(e)) => {
                    let why = format!("{study} [{}]: FAILED, {e}", v.label);
                    say!(args.progress, "bench: {why}");
                    skipped.push(why);
                    continue;
                }
                Err(panic) => {
                    let why = format!(
                        "{study} [{}]: FAILED, the bake or validation panicked: {}",
                        v.label,
                        panic_message(&*panic)
                    );
                    say!(args.progress, "bench: {why}");
                    skipped.push(why);
                    continue;
                }
            };
            say!(
                args.progress,
                "bench: foliage {study} [{}]: {} cells, median {:.1} ms/cell, {:.1} % culled, \
                 PVS/VS {}, {} false culls, {:.1} planes/cell, peak {} ({:.1} s)",
                v.label,
                row.cells,
                row.median_ms_per_cell,
                row.objects_culled_percent,
                row.pvs_over_vs.map_or("–".into(), |x| format!("{x:.2}")),
                row.false_culls,
                row.planes_per_cell,
                peak.map_or("n/a".into(), |p| format!("{p:.0} MiB")),
                t.elapsed().as_secs_f64()
            );
            if let Some(d) = &row.device {
                say!(
                    args.progress,
                    "bench: foliage {study} [{}]: device per cell: {:.0} KiB up, {:.0} KiB down \
                     ({:.1} maps read back, {:.1} sweep maps kept), setup {:.1} ms, device \
                     section {:.1} ms",
                    v.label,
                    d.kib_up_per_cell,
                    d.kib_down_per_cell,
                    d.maps_down_per_cell,
                    d.maps_kept_per_cell,
                    d.setup_ms_per_cell,
                    d.device_ms_per_cell
                );
            }
            rows.push(FoliageRow {
                study: study.into(),
                variant: v.label.clone(),
                settings: v.settings.clone(),
                row,
                peak_mib: peak,
                sampling_curve,
            });
            if let Some(doc) = doc {
                docs.push((rows.len() - 1, doc));
            }
        }
        if !docs.is_empty() {
            check_rows(&plan, args, study, &f.scene, &mut rows, &docs);
            docs.clear();
        }
    }
    if !peak_reset && rows.iter().any(|r| r.peak_mib.is_some()) {
        skipped.push(
            "peak MiB: /proc/self/clear_refs could not reset the high-water mark, so each peak \
             is the run's peak up to that bake"
                .into(),
        );
    }
    Ok(FoliageBench {
        format: "umbrasweep-bench-foliage".into(),
        studies: plan.studies.iter().map(|s| s.to_string()).collect(),
        backend: backend.name().into(),
        adapter: backend.adapter(),
        rays_per_cell: plan.rays,
        cells: plan.cells,
        subcell_cells: plan.subcell_cells,
        paper_cells: plan.paper_cells,
        model_trees: plan.model_trees,
        sampling_budget_points: plan.sampler.budget,
        sampling_max_eps: plan.sampler.max_eps,
        sampling_tuck: plan.sampler.tuck,
        sampling_eps: plan.sampler.eps,
        sampling_levels: plan.sampler.levels,
        hunt_rays: plan.hunt_rays,
        confirm_rays: plan.confirm_rays,
        trees_override: args.foliage_trees,
        seed: args.seed,
        threads: rayon::current_num_threads(),
        scenes,
        rows,
        skipped,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// The columns of a sampler row's cost curve, in order.
pub const CURVE_COLUMNS: [&str; 8] = [
    "level",
    "ε",
    "px",
    "points",
    "s",
    "hidden by the sampler",
    "% culled",
    "probe only",
];

/// The columns of each study's table, in order.
pub const COLUMNS: [&str; 12] = [
    "scene",
    "variant",
    "triangles",
    "objects",
    "cells",
    "median ms/cell",
    "% culled",
    "PVS/VS",
    "false culls",
    "planes/cell",
    "peak MiB",
    "settings",
];

impl FoliageBench {
    /// The harder checks of `study`'s rows, if any was asked for ([`super::checks_table`]).
    fn check_table(&self, out: &mut String, study: &str) {
        let rows: Vec<(String, &BenchRow)> = self
            .rows
            .iter()
            .filter(|r| r.study == study)
            .map(|r| (r.variant.clone(), &r.row))
            .collect();
        super::checks_table(out, &rows, self.hunt_rays, self.confirm_rays);
    }

    /// A header line, then per study a `### study` heading, its forest in words and a
    /// Markdown table (one row per variant), then the adapter and anything skipped.
    pub fn tables(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "umbrasweep bench --foliage: {} backend, {} cells per forest (sub-cell variants {}, \
             paper {}), {} validation rays per cell, seed {}, {} threads, {:.0} s{}",
            self.backend,
            self.cells,
            self.subcell_cells,
            self.paper_cells,
            self.rays_per_cell,
            self.seed,
            self.threads,
            self.seconds,
            match self.trees_override {
                Some(n) => format!(", TEST forests of {n} trees"),
                None => String::new(),
            }
        );
        let left: Vec<bool> = (0..COLUMNS.len())
            .map(|k| k <= 1 || k == COLUMNS.len() - 1)
            .collect();
        for study in &self.studies {
            let _ = writeln!(out, "\n### {study}\n");
            let Some(about) = self.scenes.iter().find(|s| &s.study == study) else {
                let _ = writeln!(out, "skipped (see below)");
                continue;
            };
            let _ = writeln!(out, "{}\n", about.scene);
            let cells: Vec<Vec<String>> = self
                .rows
                .iter()
                .filter(|r| &r.study == study)
                .map(|r| {
                    let b = &r.row;
                    vec![
                        b.scene.clone(),
                        r.variant.clone(),
                        b.triangles.to_string(),
                        b.objects.to_string(),
                        b.cells.to_string(),
                        format!("{:.1}", b.median_ms_per_cell),
                        format!("{:.1}", b.objects_culled_percent),
                        b.pvs_over_vs.map_or("–".into(), |v| format!("{v:.2}")),
                        b.false_culls.to_string(),
                        format!("{:.1}", b.planes_per_cell),
                        r.peak_mib.map_or("n/a".into(), |p| format!("{p:.0}")),
                        describe(&r.settings),
                    ]
                })
                .collect();
            markdown_table(&mut out, &COLUMNS, &cells, &left);
            for r in self.rows.iter().filter(|r| &r.study == study) {
                if r.sampling_curve.is_empty() {
                    continue;
                }
                let _ = writeln!(
                    out,
                    "\ncost curve of [{}] (mean per cell; each level: what a budget that ran \
                     out after it gives):\n",
                    r.variant
                );
                let rows: Vec<Vec<String>> = (r.sampling_curve.iter().enumerate())
                    .map(|(k, c)| {
                        vec![
                            k.to_string(),
                            format!("{:.4}", c.eps),
                            c.resolution.to_string(),
                            format!("{:.0}", c.points),
                            format!("{:.1}", c.seconds),
                            format!("{:.1}", c.sampler_hidden),
                            format!("{:.1}", c.objects_culled_percent),
                            if c.probe_only > 0.0 {
                                format!("{:.0} %", 100.0 * c.probe_only)
                            } else {
                                "–".into()
                            },
                        ]
                    })
                    .collect();
                markdown_table(&mut out, &CURVE_COLUMNS, &rows, &[false; 8]);
            }
            self.check_table(&mut out, study);
        }
        out.push('\n');
        if let Some(a) = &self.adapter {
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
    fn every_study_has_its_variants() {
        let labels = |s| -> Vec<String> { variants(s, 3).into_iter().map(|v| v.label).collect() };
        assert_eq!(
            labels("coarse"),
            [
                "--sweep",
                "--no-sweep",
                "--sweep --resolution 1024 --sweep-planes 32",
                "--sweep --sampling --sampling-budget 2000"
            ]
        );
        let goal = &variants("coarse", 3)[2].settings;
        assert_eq!((goal.resolution, goal.sweep_settings.planes), (1024, 32));
        assert_eq!(goal.sweep, SweepChoice::On);
        assert_eq!(labels("ellipsoid"), ["--sweep", "--no-sweep"]);
        assert_eq!(labels("jacaranda"), ["--sweep", "--no-sweep"]);
        assert_eq!(
            labels("paper"),
            ["--sweep", "--sweep --sampling --sampling-budget 2000"]
        );
        assert_eq!(
            labels("fine"),
            [
                "--sweep",
                "--sweep --subcell 2",
                "--sweep --subcell 1",
                "--sweep --subcell 0.5",
                "--no-sweep",
                "--sweep --sampling --sampling-budget 2000"
            ]
        );
        let params = variants("params", 3);
        assert_eq!(params.len(), 3 + 4 + 3 + 3 + 2);
        let default = swept(SweepChoice::On);
        for v in &params {
            // One change from the default sweep (the kernel rows: spacing, K and the cap).
            let s = &v.settings;
            let changed = [
                s.resolution != default.resolution,
                s.max_stretch != default.max_stretch,
                s.extend != default.extend,
                s.sweep_settings != default.sweep_settings,
            ];
            assert!(changed.iter().filter(|&&c| c).count() <= 1, "{}", v.label);
            assert!(s.check().is_ok(), "{}", v.label);
            assert_eq!(s.sweep, SweepChoice::On);
        }
        assert_eq!(
            params[0].label,
            "--sweep --sweep-spacing kernel --kernel 3 --sweep-planes 256"
        );
        assert_eq!(params[0].settings.sweep_settings.spacing, Spacing::Kernel);
        assert_eq!(params[0].settings.sweep_settings.planes, 256);
        assert_eq!(params[12].label, "--sweep --extend 2.0");
        assert_eq!(params[13].settings.max_stretch, 1);
        assert_eq!(
            describe(&params[13].settings),
            format!(
                "sweep ≤{} geometric, res 256, extend 1.5, stretch ≤1",
                default.sweep_settings.planes
            )
        );
        let fine = variants("fine", 3);
        assert_eq!(fine[3].settings.subcell, Some(0.5));
        assert_eq!(fine[3].max_cells, Some(3));
        assert_eq!(fine[4].settings.sweep, SweepChoice::Off);
        assert_eq!(fine[5].settings.sampling, SweepChoice::On);
        assert_eq!(fine[5].max_cells, Some(3));
        assert_eq!(
            describe(&fine[5].settings),
            format!(
                "sweep ≤{} geometric, res 256, extend 1.5, sampling ε auto, ≤2000 points",
                default.sweep_settings.planes
            )
        );
        assert_eq!(
            describe(&params[0].settings),
            "sweep ≤256 kernel K=3, res 256, extend 1.5"
        );
        assert_eq!(
            describe(&fine[1].settings),
            format!(
                "sweep ≤{} geometric, res 256, extend 1.5, subcell 2",
                default.sweep_settings.planes
            )
        );
        assert_eq!(
            describe(&fine[4].settings),
            "4+1 planes geometric, res 256, extend 1.5"
        );
    }

    #[test]
    fn spread_keeps_first_to_last_evenly() {
        assert_eq!(spread(10, Some(3)), [1, 5, 8]);
        assert_eq!(spread(2, Some(3)), [0, 1]);
        assert_eq!(spread(4, None), [0, 1, 2, 3]);
    }

    #[test]
    fn the_fine_forest_has_room_for_its_cells() {
        let g = forest(&ForestOptions {
            trees: 12,
            leaves: 8,
            cell_size: FINE_CELL,
            path_width: FINE_PATH_WIDTH,
            ..ForestOptions::fine()
        })
        .unwrap();
        assert!(!g.cells.is_empty());
        for c in &g.cells {
            assert!(
                (c.max - c.min - FINE_CELL).abs().max_element() < 1e-3,
                "{c:?}"
            );
        }
    }

    #[test]
    fn peak_memory_reads_the_high_water_mark() {
        if std::path::Path::new("/proc/self/status").is_file() {
            let p = peak_mib().unwrap();
            assert!(p > 1.0, "{p}");
        }
    }

    #[test]
    fn bad_foliage_options_are_refused() {
        let err = collect(&BenchOptions {
            foliage_studies: Some(vec!["moon".into()]),
            ..BenchOptions::default()
        })
        .unwrap_err();
        assert!(matches!(err, BenchError::UnknownStudy(_)), "{err:?}");
        assert!(err.to_string().contains("moon"), "{err}");
        let err = collect(&BenchOptions {
            foliage_paper_cells: 0,
            ..BenchOptions::default()
        })
        .unwrap_err()
        .to_string();
        assert!(err.contains("--foliage-paper-cells"), "{err}");
        for (budget, max_eps, eps, levels, flag) in [
            (0, None, None, None, "--foliage-sampling-budget"),
            (10, Some(0.0), None, None, "--foliage-sampling-max-eps"),
            (10, Some(f64::NAN), None, None, "--foliage-sampling-max-eps"),
            (10, None, Some(-1.0), None, "--foliage-sampling-eps"),
            (10, None, Some(0.0), None, "--foliage-sampling-eps"),
            (10, None, None, Some(13), "--foliage-sampling-levels"),
        ] {
            let err = collect(&BenchOptions {
                foliage_sampling_budget: budget,
                foliage_sampling_max_eps: max_eps,
                foliage_sampling_eps: eps,
                foliage_sampling_levels: levels,
                ..BenchOptions::default()
            })
            .unwrap_err()
            .to_string();
            assert!(err.contains(flag), "{err}");
        }
    }

    /// The sampler rows take the run's budget and `--sampling-max-eps`, and only they do.
    #[test]
    fn the_sampler_rows_take_the_runs_budget_and_max_eps() {
        for study in ["coarse", "fine"] {
            let plain = variants(study, 3);
            let row = SamplerRow {
                budget: 40_000,
                max_eps: Some(0.05),
                tuck: true,
                ..SamplerRow::default()
            };
            let set = with_sampler(variants(study, 3), &row);
            assert_eq!(plain.len(), set.len());
            let mut sampled = 0;
            for (p, v) in plain.iter().zip(&set) {
                if p.settings.sampling != SweepChoice::On {
                    assert_eq!(p.label, v.label);
                    assert_eq!(p.settings, v.settings);
                    continue;
                }
                sampled += 1;
                let sa = &v.settings.sampling_settings;
                assert_eq!(
                    (sa.budget_points, sa.max_eps, sa.tuck),
                    (40_000, Some(0.05), true)
                );
                assert_eq!(
                    v.label,
                    "--sweep --sampling --sampling-budget 40000 --sampling-max-eps 0.05 \
                     --sampling-tuck"
                );
                assert!(
                    describe(&v.settings).ends_with("≤40000 points, levels ε ≤0.05, tuck pass")
                );
                assert!(v.settings.check().is_ok());
            }
            assert_eq!(sampled, 1, "{study}");
            // The cost curve's range: the finest ε and the levels.
            let row = SamplerRow {
                eps: Some(0.022),
                levels: Some(4),
                ..SamplerRow::default()
            };
            let v = with_sampler(variants(study, 3), &row)
                .into_iter()
                .find(|v| v.settings.sampling == SweepChoice::On)
                .unwrap();
            assert_eq!(
                v.label,
                "--sweep --sampling --sampling-budget 2000 --sampling-eps 0.022 \
                 --sampling-levels 4"
            );
            let sa = &v.settings.sampling_settings;
            assert_eq!((sa.eps, sa.levels), (Some(0.022), 4));
            assert!(
                describe(&v.settings).ends_with("sampling ε 0.022, ≤2000 points, 4 levels"),
                "{}",
                describe(&v.settings)
            );
            assert!(v.settings.check().is_ok());
        }
    }
}
