//! The PVS as data: the JSON document `bake -o OUT.json` writes (`format: "umbrasweep-pvs"`,
//! version 1). Builds without the baking dependencies.
//!
//! Schema (documented in the README):
//! `{"format": "umbrasweep-pvs", "version": 1, "scene": PATH, "settings": {…},
//!   "objects": [{"id", "name", "triangles", "min", "max"}, …],
//!   "cells": [{"min", "max", "visible": [sorted object ids], "ms", "parent"?}, …],
//!   "summary": {…}, "split"?: {"size", "sources": […]}}` — `parent` only on the halves of
//! adaptive subdivision, `split` only with `--split-objects`.

use serde::{Deserialize, Serialize};

/// The format tag of the JSON document.
pub const FORMAT: &str = "umbrasweep-pvs";
/// The JSON schema version this crate writes and reads.
pub const VERSION: u32 = 1;

/// A whole PVS document.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PvsDocument {
    /// Always [`FORMAT`]; checked on reading.
    pub format: String,
    /// The schema version, [`VERSION`] for documents this crate writes.
    pub version: u32,
    /// The scene file the PVS was baked from.
    pub scene: String,
    /// The settings used, for reproducing the bake.
    #[serde(default)]
    pub settings: PvsSettings,
    /// The scene's objects; object `i` has id `i`.
    pub objects: Vec<PvsObject>,
    /// The cells, in bake order, each with its potentially visible set.
    pub cells: Vec<PvsCell>,
    /// Totals of the bake; absent in documents made by other tools.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub summary: Option<PvsSummary>,
    /// When the bake split objects too big to cull (`bake --split-objects SIZE`): the objects
    /// above are clusters, and this maps them back to the objects of the scene file. Absent
    /// otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub split: Option<PvsSplit>,
}

/// The clusters of a bake with `--split-objects`, mapped back to the objects of the file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PvsSplit {
    /// The cluster size given to `--split-objects`, in scene units.
    pub size: f32,
    /// The objects of the scene file, in their id order; each names its clusters.
    pub sources: Vec<PvsSource>,
}

/// One object of the scene file and the clusters (objects of the PVS) it was split into.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PvsSource {
    /// The object's id in the scene file (its index in [`PvsSplit::sources`]).
    pub id: u32,
    /// Its name in the file.
    pub name: String,
    /// Its triangle count.
    pub triangles: u32,
    /// Lower corner of its bounds.
    pub min: [f32; 3],
    /// Upper corner of its bounds.
    pub max: [f32; 3],
    /// Its clusters: the PVS object ids `first .. first + count` (contiguous; the sources'
    /// ranges follow each other and cover every object).
    pub first: u32,
    /// How many clusters it became (1 when it was left whole).
    pub count: u32,
}

impl PvsSplit {
    /// The object of the file that PVS object (cluster) `object` belongs to.
    pub fn source_of(&self, object: u32) -> u32 {
        self.sources
            .partition_point(|s| s.first + s.count <= object) as u32
    }

    /// The objects of the file visible when the clusters `visible` (ascending) are: each
    /// source object once, ascending.
    pub fn source_visible(&self, visible: &[u32]) -> Vec<u32> {
        let mut out: Vec<u32> = visible.iter().map(|&o| self.source_of(o)).collect();
        out.dedup();
        out
    }
}

/// One scene object, as the PVS numbers it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PvsObject {
    /// The object's id: its index in the scene (and in [`PvsDocument::objects`]).
    pub id: u32,
    /// The object's name in the scene (may be empty).
    pub name: String,
    /// Triangle count of the object.
    pub triangles: u32,
    /// Lower corner of the world bounds (`+inf` for an object without triangles).
    pub min: [f32; 3],
    /// Upper corner of the world bounds (`-inf` for an object without triangles).
    pub max: [f32; 3],
}

/// One cell and its potentially visible set.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PvsCell {
    /// Lower corner of the cell, in scene units.
    pub min: [f32; 3],
    /// Upper corner of the cell, in scene units.
    pub max: [f32; 3],
    /// Ids of the potentially visible objects, sorted ascending.
    pub visible: Vec<u32>,
    /// Milliseconds spent baking this cell.
    #[serde(default)]
    pub ms: f64,
    /// With adaptive subdivision (`--max-pvs-triangles`): the cell this one is a half of
    /// (always an earlier cell), absent for the cells given to the bake. The run-time lookup
    /// descends from a given cell to the smallest cell holding the point.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parent: Option<u32>,
    /// Per culler, what it did in this cell (JSON documents from bakes that ran the
    /// shrunk-occluder sampler; absent otherwise and in `.pvs` files).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub cullers: Vec<PvsCellCuller>,
}

/// One culler's account for one cell of a PVS document.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PvsCellCuller {
    /// The culler's name, as in `summary.cullers`.
    pub name: String,
    /// Objects culled from the cell that this culler proved hidden.
    pub hidden: u32,
    /// Milliseconds it ran in the cell.
    pub ms: f64,
    /// Sample points it rendered (the shrunk-occluder sampler).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub points: u64,
    /// The finest ε it rendered (the sampler), in scene units.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub finest_eps: Option<f64>,
    /// The sampler's cost curve: one entry per refinement level it sampled, coarsest first
    /// (absent for other cullers and for cells baked in sub-cells).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub levels: Vec<SamplingLevel>,
}

/// One refinement level of the shrunk-occluder sampler in one cell: what a budget that ran
/// out right after this level would have given. Levels are sampled breadth-first, so these
/// are the points of the cell's cost curve (budget → objects culled).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SamplingLevel {
    /// The largest ε of the level's sample points (their rectangles' half diagonals).
    pub eps: f64,
    /// Pixels across each 90° view of the hemicubes rendered at this level (0 in documents
    /// written before it was recorded).
    #[serde(default)]
    pub resolution: u32,
    /// Sample points rendered up to the end of this level (all levels so far).
    pub points: u64,
    /// Seconds of sampling up to the end of this level (0 with `--reproducible`).
    pub seconds: f64,
    /// Objects the sampler had proved hidden from every face by the end of this level (the
    /// last level's count is what it hid).
    pub hidden: u32,
    /// Only the level's probe was sampled: it proved too little (`sampling_probe`), and the
    /// rest of the level was split without sampling.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub probe_only: bool,
    /// The level's probe (every 16th rectangle, for levels but the finest): the share of its
    /// object tests that proved the object hidden at the rectangle. What `--sampling-probe`
    /// compares; absent for a level without a probe.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe_hidden: Option<f64>,
    /// The level's probe: the objects still undecided that every probed rectangle testing
    /// them proved hidden (what the level would have culled for the cell had it been only its
    /// probe). Absent for a level without a probe.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe_cell_hidden: Option<u32>,
    /// The level's probe: the objects still undecided that some probed rectangle tested.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe_objects: Option<u32>,
    /// The level's probe: the rectangles it sampled. Fewer than every 16th (about 64 at most)
    /// where it stopped early, once the rest could prove nothing (absent in documents written
    /// before it was recorded, and for a level without a probe).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe_rects: Option<u32>,
    /// The level's pilot (`sampling_probe_pay`): what sampling one more of its rectangles
    /// costs, in polygons drawn weighted by resolution (`SamplingSettings::polygon_weight`).
    /// Absent where no pilot ran (no probe, a probe that stopped the level already, or the
    /// estimate off).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe_cost: Option<f64>,
    /// The level's pilot: what one of its rectangles was estimated to save the finest level,
    /// in the same weighted polygons. The rest of the level was sampled only when this was at
    /// least `sampling_probe_pay` × `probe_cost`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pilot_saving: Option<f64>,
}

fn is_zero(v: &u64) -> bool {
    *v == 0
}

/// Totals over all cells.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct PvsSummary {
    /// Number of cells baked.
    pub cells: usize,
    /// Number of objects in the scene.
    pub objects: usize,
    /// Number of triangles in the scene.
    pub triangles: usize,
    /// Triangles used as occluders (opaque, selected, not degenerate).
    pub occluder_triangles: usize,
    /// Zero-area triangles skipped.
    pub degenerate_triangles: usize,
    /// The backend that baked (e.g. `cpu` or `gpu`).
    pub backend: String,
    /// The GPU adapter's description; `None` for the CPU backend.
    pub adapter: Option<String>,
    /// Mean over cells of the percentage of objects culled.
    pub objects_culled_percent: f64,
    /// Mean over cells of the percentage of triangles culled.
    pub triangles_culled_percent: f64,
    /// Median over cells of the bake time per cell, in milliseconds.
    pub median_ms_per_cell: f64,
    /// Wall time of the whole bake, in seconds.
    pub total_seconds: f64,
    /// The cullers every cell ran, in order, with their mean account per cell (absent in
    /// documents written before the culler pipeline).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub cullers: Vec<PvsCullerSummary>,
    /// What the alpha-tested cards gave as occluders, when the scene has cards and the bake
    /// used their coverage (not kept in `.pvs` files).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alpha_cards: Option<PvsCardSummary>,
}

/// The alpha-tested cards' account in a PVS document's summary.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PvsCardSummary {
    /// Card triangles of occluder objects.
    pub triangles: usize,
    /// Surely opaque polygons made from them.
    pub polygons: usize,
    /// Share of the cards' world-space area those polygons cover (the rest is transparent or
    /// not surely opaque at every trusted mip level).
    pub opaque_share: f64,
}

/// The culler name ([`PvsCullerSummary::name`]) of extended projections on separate planes.
pub const EXTENDED_PROJECTIONS: &str = "extended_projections";
/// The culler name of the occlusion sweep.
pub const OCCLUSION_SWEEP: &str = "occlusion_sweep";
/// The culler name of shrunk-occluder sampling.
pub const SHRUNK_SAMPLING: &str = "shrunk_sampling";
/// The culler name of ray space factorization.
pub const RAY_SPACE_FACTORIZATION: &str = "ray_space_factorization";

/// One culler's account in a PVS document's summary: means per cell.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PvsCullerSummary {
    /// The culler ([`EXTENDED_PROJECTIONS`], [`OCCLUSION_SWEEP`], …).
    pub name: String,
    /// Objects culled from a cell that this culler proved hidden, mean per cell.
    pub hidden: f64,
    /// Of those, the objects no other culler proved hidden (a culler does not test what an
    /// earlier one hid), mean per cell.
    pub only: f64,
    /// Milliseconds it ran, mean per cell.
    pub ms: f64,
    /// Planes it rasterised, mean per cell.
    #[serde(default)]
    pub planes: f64,
    /// Sample points it rendered, mean per cell (the shrunk-occluder sampler; not kept in
    /// `.pvs` files).
    #[serde(default, skip_serializing_if = "is_zero_f64")]
    pub points: f64,
    /// The finest ε it rendered in any cell (the sampler; not kept in `.pvs` files).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub finest_eps: Option<f64>,
    /// The sampler's mean cost curve over the cells ([`SamplingLevel`] per level; not kept in
    /// `.pvs` files).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub levels: Vec<PvsLevelSummary>,
    /// The sampler on the GPU backend: why some cell's renders ran on the CPU's hemicube
    /// instead (the device could not make a GPU sampler at a level's resolution, or the tuck
    /// pass, which has no GPU twin, was on), the first such reason; absent when none did (not kept in `.pvs` files).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cpu_fallback: Option<String>,
}

/// One level of the sampler's mean cost curve: means over the cells of their
/// [`SamplingLevel`] at that level (a cell whose sampling stopped earlier counts with its
/// last level), and the largest ε.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PvsLevelSummary {
    /// The largest ε of the level's sample points in any cell.
    pub eps: f64,
    /// The largest resolution rendered at the level in any cell (pixels across each 90°
    /// view; 0 in documents written before it was recorded).
    #[serde(default)]
    pub resolution: u32,
    /// Sample points up to the end of the level, mean per cell.
    pub points: f64,
    /// Seconds of sampling up to the end of the level, mean per cell.
    pub seconds: f64,
    /// Objects proved hidden by the end of the level, mean per cell.
    pub hidden: f64,
    /// The share of those cells where only the level's probe was sampled
    /// ([`SamplingLevel::probe_only`]; 0 in documents written before probes).
    #[serde(default)]
    pub probe_only: f64,
    /// Mean over the cells whose level had a probe of [`SamplingLevel::probe_hidden`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe_hidden: Option<f64>,
    /// Mean over the cells whose level had a probe of [`SamplingLevel::probe_cell_hidden`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe_cell_hidden: Option<f64>,
    /// Mean over the cells whose level had a probe of [`SamplingLevel::probe_objects`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe_objects: Option<f64>,
    /// Mean over the cells whose level had a probe of [`SamplingLevel::probe_rects`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe_rects: Option<f64>,
    /// Mean over the cells whose level had a pilot of [`SamplingLevel::probe_cost`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe_cost: Option<f64>,
    /// Mean over the cells whose level had a pilot of [`SamplingLevel::pilot_saving`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pilot_saving: Option<f64>,
}

fn is_zero_f64(v: &f64) -> bool {
    *v == 0.0
}

/// The bake settings recorded in a PVS document: the backend that ran and the
/// [`BakeSettings`](crate::settings::BakeSettings) themselves, flattened beside it, with `sweep`
/// as the bake chose it (`true` or `false`). Fields a document lacks read as the bake that
/// wrote it ran ([`crate::settings`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct PvsSettings {
    /// The backend that baked (`cpu` or `gpu`).
    pub backend: String,
    /// The settings of the bake.
    #[serde(flatten)]
    pub bake: crate::settings::BakeSettings,
}

impl Default for PvsSettings {
    /// What a document without settings reads as: the defaults, as a bake without the sweep,
    /// without the sampler, without ray space factorization and with square maps ran (the
    /// reading of fields older documents lack).
    fn default() -> Self {
        PvsSettings {
            backend: String::new(),
            bake: crate::settings::BakeSettings {
                sweep: crate::settings::SweepChoice::Off,
                sampling: crate::settings::SweepChoice::Off,
                rsf: crate::settings::SweepChoice::Off,
                max_stretch: 1,
                ..crate::settings::BakeSettings::default()
            },
        }
    }
}

// Imports run one way: `format` (byte-level definitions) ← `error` ← `database` (reader) ←
// `binary` (writer); `json` uses `error`; all use the document types above.
pub mod binary;
pub mod database;
mod error;
pub mod format;
#[cfg(feature = "bake")]
pub mod json;

pub use database::{CellId, PvsCursor, PvsDatabase};
pub use error::{EncodeError, PvsError, PvsErrorKind};
#[cfg(feature = "bake")]
pub use error::{PvsJsonError, PvsJsonErrorKind, PvsWriteError, PvsWriteErrorKind};
