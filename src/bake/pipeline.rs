//! The per-cell pipeline of cullers. A cell's culling runs an ordered list of [`Culler`]s
//! ([`cullers`] builds it from the settings): each gets the objects still potentially visible
//! (those not yet in [`CullState::hidden`]) and the occluders still useful (hidden objects
//! occlude nothing a later culler needs: leaving an occluder out is always conservative), and
//! marks what it proves hidden. Later cullers skip what earlier ones hid. The bake records per
//! culler and cell what it hid, what only it hid and its time ([`CullerStats`]).
//!
//! # Adding a culler
//! Write a module in `src/bake/` with a type implementing [`Culler`] (its module docs say why
//! it is conservative), give it a switch in [`BakeSettings`] and push it in [`cullers`] at its
//! place in the order. The bake loop, the accounting, the PVS document, the `.pvs` file and the
//! report need no change.

use super::prepare::Prepared;
use super::{BakeError, BakeSettings};
use crate::backend::RasterBackend;
use crate::geom::Aabb;
use crate::hdm::Hdm;
use crate::plane::{DepthMap, PlaneJob};

/// The state one (sub-)cell's cullers share.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CullState<'k> {
    /// Per object: proven hidden from the (sub-)cell by a culler that ran before.
    pub hidden: Vec<bool>,
    /// Objects already known visible from another part of the cell (with sub-cells): their
    /// result does not matter, so they need not be tested, but they still occlude.
    pub known_visible: Option<&'k [bool]>,
}

/// What one culler did in one (sub-)cell, besides hiding objects.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CullerWork {
    /// Planes rasterised.
    pub planes: usize,
    /// Occluder Projections sent to the backend.
    pub occluders_projected: usize,
    /// Sample points rendered (the shrunk-occluder sampler).
    pub points: u64,
    /// Occluder polygons drawn, summed over the sample points (the sampler).
    pub polygons: u64,
    /// The finest ε rendered (the sampler; `None` when it rendered nothing).
    pub finest_eps: Option<f64>,
    /// The sampler's cost curve, one entry per level it sampled (empty for other cullers and
    /// for a cell baked in sub-cells).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub levels: Vec<crate::pvs::SamplingLevel>,
    /// The sampler on the GPU backend: why some of its renders ran on the CPU's hemicube (the
    /// device could not make a GPU sampler at a level's resolution, or the tuck pass was on;
    /// the first reason), `None`
    /// when none did. The answers are the same either way.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cpu_fallback: Option<String>,
    /// Milliseconds earlier runs spent on this cell's work, as its checkpoint recorded (the
    /// sampler resumed by `bake --resume`): the pipeline adds them to the culler's time and
    /// the cell's, so that a resumed cell reports what it cost in all.
    #[serde(skip)]
    pub resumed_ms: f64,
}

impl CullerWork {
    /// Adds `o`'s work (the finest ε is the smaller). Cost curves do not add up and are left
    /// as they are (the pipeline keeps a cell's curve only when the cell ran once).
    pub fn add(&mut self, o: &CullerWork) {
        self.planes += o.planes;
        self.occluders_projected += o.occluders_projected;
        self.points += o.points;
        self.polygons += o.polygons;
        self.resumed_ms += o.resumed_ms;
        self.finest_eps = match (self.finest_eps, o.finest_eps) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        };
        if self.cpu_fallback.is_none() {
            self.cpu_fallback.clone_from(&o.cpu_fallback);
        }
    }
}

/// One culler's account for one cell.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CullerStats {
    /// Objects culled from the cell that this culler proved hidden (in some sub-cell).
    pub hidden: u32,
    /// Of those, the objects no other culler of the pipeline proved hidden. A culler does not
    /// test what an earlier one hid, so this counts what the others were not asked about too.
    pub only: u32,
    /// Milliseconds this culler ran in the cell (all its sub-cells), with what earlier runs
    /// spent on it when the sampler resumed the cell from a checkpoint
    /// ([`CullerWork::resumed_ms`]).
    pub ms: f64,
    /// Planes rasterised and occluder Projections sent.
    pub work: CullerWork,
}

// The cullers' names ([`Culler::name`]) live with the PVS document, which records them and
// which the run-time library reads without the bake.
pub use crate::pvs::{
    EXTENDED_PROJECTIONS, OCCLUSION_SWEEP, RAY_SPACE_FACTORIZATION, SHRUNK_SAMPLING,
};

/// Every name a culler of the pipeline may have ([`Culler::name`]); files that record the
/// cullers (shards) are read back against this list.
pub const CULLER_NAMES: [&str; 4] = [
    EXTENDED_PROJECTIONS,
    OCCLUSION_SWEEP,
    SHRUNK_SAMPLING,
    RAY_SPACE_FACTORIZATION,
];

/// Deserialises culler names as the [`CULLER_NAMES`] they are, refusing unknown ones.
pub(super) fn culler_names<'de, D>(d: D) -> Result<Vec<&'static str>, D::Error>
where
    D: serde::Deserializer<'de>,
{
    let names: Vec<String> = serde::Deserialize::deserialize(d)?;
    names
        .iter()
        .map(|n| {
            CULLER_NAMES
                .iter()
                .copied()
                .find(|k| k == n)
                .ok_or_else(|| serde::de::Error::custom(format!("unknown culler {n:?}")))
        })
        .collect()
}

/// One culler of the pipeline: proves objects hidden from a (sub-)cell.
///
/// Implementations must be conservative: an object marked hidden must be invisible from every
/// point of `cell`. They may rely on what earlier cullers marked hidden (it is), and must not
/// unmark anything.
pub trait Culler: Send + Sync {
    /// The name the accounting records (`summary.cullers[].name` in the PVS document).
    fn name(&self) -> &'static str;

    /// Culls from `cell`: marks in `state.hidden` what it proves hidden, hands every plane it
    /// renders to `observe` (dumps and reports; cullers without planes ignore it).
    ///
    /// # Errors
    /// The backend's failure.
    fn cull(
        &self,
        prepared: &Prepared,
        cell: &Aabb,
        backend: &dyn RasterBackend,
        state: &mut CullState,
        observe: &mut dyn PlaneSink,
    ) -> Result<CullerWork, BakeError>;

    /// A line for the bake's summary about what the culler shared over the whole bake (such as
    /// the sampler's GPU memory), or `None`. Not in the PVS document: it depends on the
    /// threads.
    fn note(&self) -> Option<String> {
        None
    }
}

/// What a culler hands its rendered planes to: dumps and reports ([`super::Prepared::cell_observed`]).
/// Any `FnMut(&PlaneJob, &DepthMap, &Hdm)` is one that wants every plane's map; [`NoPlanes`]
/// wants none, which lets a backend answer the occludee tests of separate planes on its
/// device and keep their maps there ([`RasterBackend::render_tested`]).
pub trait PlaneSink {
    /// True when every rendered plane's Depth Map must come back to [`Self::plane`].
    fn wants_maps(&self) -> bool;
    /// A rendered plane: its job, its Depth Map and its Hierarchical Depth Map, before its
    /// occludees are tested.
    fn plane(&mut self, job: &PlaneJob, map: &DepthMap, hdm: &Hdm);
}

impl<F: FnMut(&PlaneJob, &DepthMap, &Hdm)> PlaneSink for F {
    fn wants_maps(&self) -> bool {
        true
    }

    fn plane(&mut self, job: &PlaneJob, map: &DepthMap, hdm: &Hdm) {
        self(job, map, hdm);
    }
}

/// A [`PlaneSink`] that wants no plane (a plain bake).
#[derive(Clone, Copy, Debug, Default)]
pub struct NoPlanes;

impl PlaneSink for NoPlanes {
    fn wants_maps(&self) -> bool {
        false
    }

    fn plane(&mut self, _: &PlaneJob, _: &DepthMap, _: &Hdm) {}
}

/// The cullers of a bake, in order: ray space factorization where `rsf`; the occlusion sweep
/// where `sweep` (what [`super::SweepChoice`] and the automatic rule chose), else extended
/// projections on separate planes; then the shrunk-occluder sampler where `sampling` (on
/// what is still visible).
pub fn cullers(
    _settings: &BakeSettings,
    rsf: bool,
    sweep: bool,
    sampling: bool,
) -> Vec<Box<dyn Culler>> {
    let mut out: Vec<Box<dyn Culler>> = Vec::new();
    if rsf {
        out.push(Box::new(super::rsf::RsfCuller));
    }
    out.push(Box::new(super::planes::PlaneCuller { sweep }));
    if sampling {
        out.push(Box::new(super::sampling::SamplingCuller::default()));
    }
    out
}

/// A cell's accounting while its sub-cells run: per culler its stats, per object the set of
/// cullers that hid it (bit `k` for culler `k`) in some sub-cell.
pub(super) struct CellAccount {
    stats: Vec<CullerStats>,
    hid_by: Vec<u64>,
    /// Pipeline runs added up (sub-cells).
    runs: usize,
}

impl CellAccount {
    /// An empty account for `cullers` cullers (at most 64) and `objects` objects.
    pub(super) fn new(cullers: usize, objects: usize) -> Self {
        assert!(cullers <= 64, "at most 64 cullers");
        CellAccount {
            stats: vec![CullerStats::default(); cullers],
            hid_by: vec![0; objects],
            runs: 0,
        }
    }

    /// The stats, with `hidden` and `only` counted over the objects culled from the cell
    /// (`visible[o]` false).
    pub(super) fn finish(mut self, visible: &[bool]) -> Vec<CullerStats> {
        for (&bits, _) in self
            .hid_by
            .iter()
            .zip(visible)
            .filter(|(b, v)| **b != 0 && !**v)
        {
            for (k, s) in self.stats.iter_mut().enumerate() {
                if bits & (1 << k) != 0 {
                    s.hidden += 1;
                    if bits == 1 << k {
                        s.only += 1;
                    }
                }
            }
        }
        self.stats
    }
}

/// Runs `cullers` over one (sub-)cell, adding to `account`. Returns the objects hidden.
/// `inherited` are objects already proven hidden from a box holding the cell (the parent of
/// a subdivided cell): they start hidden, are not tested and do not occlude.
///
/// # Errors
/// A culler's failure.
#[expect(
    clippy::too_many_arguments,
    reason = "the pipeline's inputs, each distinct"
)]
pub(super) fn run(
    cullers: &[Box<dyn Culler>],
    prepared: &Prepared,
    cell: &Aabb,
    backend: &dyn RasterBackend,
    known_visible: Option<&[bool]>,
    inherited: Option<&[bool]>,
    observe: &mut dyn PlaneSink,
    account: &mut CellAccount,
) -> Result<Vec<bool>, BakeError> {
    let n = prepared.scene.objects.len();
    let mut state = CullState {
        hidden: inherited.map_or_else(|| vec![false; n], <[bool]>::to_vec),
        known_visible,
    };
    for (k, culler) in cullers.iter().enumerate() {
        let before = state.hidden.clone();
        let start = std::time::Instant::now();
        let work = culler.cull(prepared, cell, backend, &mut state, observe)?;
        let s = &mut account.stats[k];
        s.ms += start.elapsed().as_secs_f64() * 1e3 + work.resumed_ms;
        s.work.add(&work);
        // Sub-cells' cost curves do not add up (an object is culled only when every sub-cell
        // hid it): a cell baked in sub-cells has none.
        s.work.levels = if account.runs == 0 {
            work.levels
        } else {
            Vec::new()
        };
        for (o, (&now, &was)) in state.hidden.iter().zip(&before).enumerate() {
            debug_assert!(now || !was, "{} unmarked object {o}", culler.name());
            if now && !was {
                account.hid_by[o] |= 1 << k;
            }
        }
    }
    account.runs += 1;
    Ok(state.hidden)
}
