//! The per-scene preparation shared by every cell of a bake ([`Prepared`]: occluder parts,
//! sliceable objects, a BVH over object bounds, occludee pieces, the cullers), the automatic
//! choice of the occlusion sweep ([`choose_sweep`]), and the per-cell driver that runs the
//! culler pipeline on each cell or on each of its sub-cells.

use super::pipeline::{self, CellAccount, Culler, PlaneSink};
use super::{BakeError, BakeSettings, CellResult, SweepChoice};
use crate::backend::RasterBackend;
use crate::geom::{Aabb, DAabb};
use crate::project::occluders::{self, Occluders};
use crate::project::planes::Sliceable;
use crate::scene::Scene;
use crate::settings::{SamplingFusion, SamplingSettings};
use obvhs::bvh2::Bvh2;
use std::time::Instant;

/// The per-scene preparation shared by all cells.
pub struct Prepared<'a> {
    /// The scene being baked.
    pub scene: &'a Scene,
    /// The convex occluder parts of the scene.
    pub occluders: Occluders,
    /// Objects whose cross-sections may serve as slices.
    pub sliceable: Sliceable,
    pub(super) bvh: Option<Bvh2>,
    pub(super) settings: BakeSettings,
    /// The cullers every cell runs, in order ([`pipeline::cullers`]).
    pub(super) cullers: Vec<Box<dyn Culler>>,
    /// Whether cells are baked with the occlusion sweep, and why.
    pub sweep: bool,
    /// Why cells are swept or not, one human-readable line.
    pub sweep_reason: String,
    /// Whether cells run ray space factorization first.
    pub rsf: bool,
    /// Why ray space factorization runs or not, one human-readable line.
    pub rsf_reason: String,
    /// Whether cells run the shrunk-occluder sampler.
    pub sampling: bool,
    /// Why the sampler runs or not (and its ε), one human-readable line.
    pub sampling_reason: String,
    /// The sampler's per-scene data (with `sampling`).
    pub(super) sampler: Option<super::sampling::SamplerData>,
    /// With ray space factorization: per occluder part, a solid's hull edges (empty for
    /// polygons and without it).
    pub(super) rsf_edges: Vec<Vec<(usize, usize)>>,
    /// Per object, its pieces in `piece_boxes` (empty for small objects): boxes around parts of
    /// its triangles, tested when the object's own box is not hidden.
    pub(super) pieces: Vec<std::ops::Range<u32>>,
    pub(super) piece_boxes: Vec<DAabb>,
    /// Per piece, its triangles: a range of `piece_triangles` (scene triangle indices).
    pub(super) piece_triangle_ranges: Vec<std::ops::Range<u32>>,
    pub(super) piece_triangles: Vec<u32>,
    /// Per object, its occluder parts (indices into `occluders.parts`).
    pub(super) object_parts: Vec<Vec<u32>>,
    /// A box holding every object: planes' rectangles stop where no ray toward it passes
    /// ([`crate::project::planes::DirectionPlan::relevant_rect`]).
    pub(super) bounds: DAabb,
    /// Where the sampler counts its points and rectangles for progress
    /// ([`super::BakeHooks`]).
    pub(super) sampler_progress: Option<&'a super::SamplerProgress>,
    /// Where the sampler saves its progress inside cells ([`super::BakeHooks`]).
    pub(super) checkpoints: Option<&'a super::SamplerCheckpoints>,
    /// The generation of the backend's copy of [`Prepared::occludee_boxes`], where it keeps
    /// one ([`crate::backend::RasterBackend::upload_occludee_boxes`]): box tests then name
    /// boxes by index.
    pub(super) occludee_table: Option<u64>,
    /// The generation of the backend's copy of the occluder parts' points, where it keeps
    /// one ([`crate::backend::RasterBackend::upload_occluder_parts`]): jobs then name parts by
    /// index.
    pub(super) occluder_table: Option<u64>,
}

/// Objects with at least this many triangles are also tested as pieces.
pub const PIECE_MIN_TRIANGLES: usize = 16;
/// Median splits per object for its pieces (at most `2^PIECE_LEVELS` pieces).
pub const PIECE_LEVELS: u32 = 4;

/// Boxes around pieces of each object's triangles: median splits of the triangles' centres
/// along the longest axis, [`PIECE_LEVELS`] deep. An object is hidden when all its pieces are,
/// each possibly on another plane: the union of the pieces holds every triangle, so this is as
/// conservative as testing the object's box, and much tighter for round or hollow objects (a
/// tree crown's box has empty corners that low rays see under the other crowns).
fn object_pieces(scene: &Scene) -> Pieces {
    let mut out = Pieces::default();
    for o in &scene.objects {
        let start = out.boxes.len() as u32;
        if o.triangles.len() >= PIECE_MIN_TRIANGLES {
            let mut tris: Vec<(glam::DVec3, DAabb, u32)> = o
                .triangles
                .clone()
                .map(|t| {
                    let [a, b, c] = scene.triangle(t as usize).map(|p| p.as_dvec3());
                    let bx = DAabb {
                        min: a.min(b).min(c),
                        max: a.max(b).max(c),
                    };
                    ((a + b + c) / 3.0, bx, t)
                })
                .collect();
            split_pieces(&mut tris, PIECE_LEVELS, &mut out);
        }
        out.ranges.push(start..out.boxes.len() as u32);
    }
    out
}

/// Every object's pieces: per object its range of pieces, per piece its box and its range
/// of `triangles` (the scene's triangle indices).
#[derive(Default)]
struct Pieces {
    ranges: Vec<std::ops::Range<u32>>,
    boxes: Vec<DAabb>,
    triangle_ranges: Vec<std::ops::Range<u32>>,
    triangles: Vec<u32>,
}

fn split_pieces(tris: &mut [(glam::DVec3, DAabb, u32)], levels: u32, out: &mut Pieces) {
    if tris.is_empty() {
        return;
    }
    let mut b = tris[0].1;
    for t in tris.iter() {
        b.min = b.min.min(t.1.min);
        b.max = b.max.max(t.1.max);
    }
    if levels == 0 || tris.len() < 4 {
        out.boxes.push(b);
        let start = out.triangles.len() as u32;
        out.triangles.extend(tris.iter().map(|t| t.2));
        out.triangle_ranges.push(start..out.triangles.len() as u32);
        return;
    }
    let axis = (b.max - b.min).max_position();
    let mid = tris.len() / 2;
    tris.select_nth_unstable_by(mid, |x, y| x.0[axis].total_cmp(&y.0[axis]));
    let (lo, hi) = tris.split_at_mut(mid);
    split_pieces(lo, levels - 1, out);
    split_pieces(hi, levels - 1, out);
}

/// Why [`SweepChoice::Auto`] leaves the shrunk-occluder sampler off for now (issue 16: the
/// intended rule is "on where the sweep's rule picks the sweep", once it pays for its time).
pub const SAMPLING_AUTO_NOTE: &str = "it costs minutes to an hour per cell on the CPU: 2 min on two cores to cull 71 % of a fine forest's 1-unit cell, where the sweep culls 0 %";

/// Small occluders: parts whose largest side is under this many times the median cell's
/// largest side.
pub const SMALL_OCCLUDER_CELLS: f64 = 2.0;
/// The sweep is chosen when small occluders hold at least this share of the occluders' area.
pub const SMALL_OCCLUDER_SHARE: f64 = 0.5;

/// The rule of [`SweepChoice::Auto`]: sweep when occluder parts (convex polygons and solids)
/// smaller than [`SMALL_OCCLUDER_CELLS`] × the median cell's largest side hold at least
/// [`SMALL_OCCLUDER_SHARE`] of the occluders' area (each part weighted by the square of its
/// largest side). Leaves next to a cell fuse only through the sweep; walls and boxes larger than
/// the cell hide on their own, and separate planes fitted to them cull more. Returns the choice
/// and a sentence for the summary.
pub fn choose_sweep(occ: &Occluders, cells: &[Aabb]) -> (bool, String) {
    let mut sides: Vec<f64> = cells
        .iter()
        .map(|c| (c.max - c.min).max_element() as f64)
        .collect();
    if sides.is_empty() || occ.parts.is_empty() {
        return (false, "no cells or no occluders".into());
    }
    sides.sort_by(f64::total_cmp);
    let cell = sides[sides.len() / 2];
    let limit = SMALL_OCCLUDER_CELLS * cell;
    let (mut small, mut total) = (0.0, 0.0);
    for p in &occ.parts {
        let e = (p.bounds.max - p.bounds.min).max_element();
        total += e * e;
        if e < limit {
            small += e * e;
        }
    }
    let share = if total > 0.0 { small / total } else { 0.0 };
    let sweep = share >= SMALL_OCCLUDER_SHARE;
    (
        sweep,
        format!(
            "{:.0} % of the occluder area is in parts smaller than {limit:.3} ({SMALL_OCCLUDER_CELLS} × the median cell side {cell:.3}); the sweep is chosen from {:.0} %",
            100.0 * share,
            100.0 * SMALL_OCCLUDER_SHARE
        ),
    )
}

struct ObjBox(obvhs::aabb::Aabb);
impl obvhs::Boundable for ObjBox {
    fn aabb(&self) -> obvhs::aabb::Aabb {
        self.0
    }
}

/// Whether `corners` occluder corners fit the occluder tables' `u32` indices.
///
/// # Errors
/// [`BakeError::TooManyOccluderCorners`] past `u32::MAX`.
fn check_occluder_corners(corners: u64) -> Result<(), BakeError> {
    if corners > u64::from(u32::MAX) {
        return Err(BakeError::TooManyOccluderCorners(corners));
    }
    Ok(())
}

impl<'a> Prepared<'a> {
    /// Prepares a scene for baking with `settings`.
    ///
    /// # Errors
    /// Invalid settings, an occluder pattern that is not a valid glob, or occluders with more
    /// than `u32::MAX` corners.
    /// [`SweepChoice::Auto`] is decided here with [`choose_sweep`] on `cells`.
    pub fn new(
        scene: &'a Scene,
        settings: &BakeSettings,
        cells: &[Aabb],
    ) -> Result<Self, BakeError> {
        settings.check().map_err(BakeError::Settings)?;
        let is_occluder: Vec<bool> = match &settings.occluders {
            None => vec![true; scene.objects.len()],
            Some(pat) => {
                let glob = globset::Glob::new(pat)
                    .map_err(|e| {
                        BakeError::Settings(crate::settings::SettingsError {
                            option: "occluders",
                            value: format!("{pat:?}"),
                            expected: format!("not a valid pattern: {e}"),
                        })
                    })?
                    .compile_matcher();
                scene
                    .objects
                    .iter()
                    .map(|o| glob.is_match(&o.name))
                    .collect()
            }
        };
        let cards = (settings.alpha_cards == crate::settings::AlphaCards::Coverage).then(|| {
            crate::scene::alpha::CardOptions {
                mips: (settings.alpha_mips > 0).then_some(settings.alpha_mips),
                max_polygons: settings.alpha_card_polygons as usize,
                min_share: crate::scene::alpha::MIN_POLYGON_SHARE,
            }
        });
        // The occluder tables index their points with `u32`: a bound before the preparation
        // (a part has at most its triangles' corners) and the count after it (cards add points).
        let corners: u64 = scene
            .objects
            .iter()
            .zip(&is_occluder)
            .filter(|&(_, &o)| o)
            .map(|(ob, _)| 3 * u64::from(ob.triangles.end - ob.triangles.start))
            .sum();
        check_occluder_corners(corners)?;
        let occluders =
            occluders::prepare_with(scene, &is_occluder, settings.alpha_occluders, cards);
        check_occluder_corners(occluders.points.len() as u64)?;
        let sliceable = Sliceable::new(scene, &is_occluder, settings.alpha_occluders);
        let boxes: Vec<ObjBox> = scene
            .objects
            .iter()
            .map(|o| {
                let b = if o.bounds.is_empty() {
                    Aabb::new(glam::Vec3::ZERO, glam::Vec3::ZERO)
                } else {
                    o.bounds
                };
                ObjBox(obvhs::aabb::Aabb::new(b.min.into(), b.max.into()))
            })
            .collect();
        let bvh = if boxes.is_empty() {
            None
        } else {
            let mut t = std::time::Duration::ZERO;
            Some(obvhs::bvh2::builder::build_bvh2(
                &boxes,
                obvhs::BvhBuildParams::fastest_build(),
                &mut t,
            ))
        };
        let rule = choose_sweep(&occluders, cells);
        let (sweep, sweep_reason) = match settings.sweep {
            SweepChoice::On => (true, "--sweep".to_string()),
            SweepChoice::Off => (false, "--no-sweep".to_string()),
            SweepChoice::Auto => rule.clone(),
        };
        let (sampling, mut sampling_reason) = match settings.sampling {
            SweepChoice::On => (true, "--sampling".to_string()),
            SweepChoice::Off => (false, "--no-sampling".to_string()),
            SweepChoice::Auto => (
                false,
                format!("off by default ({SAMPLING_AUTO_NOTE}; --sampling turns it on)"),
            ),
        };
        let (rsf, rsf_reason) = match settings.rsf {
            SweepChoice::On => (true, "--rsf".to_string()),
            SweepChoice::Off => (false, "--no-rsf".to_string()),
            SweepChoice::Auto => super::rsf::choose_rsf(&occluders, settings.up.index()),
        };
        let sampler = sampling.then(|| {
            let d = super::sampling::SamplerData::new(&occluders, scene, settings);
            sampling_reason = format!(
                "{sampling_reason}; finest ε {:.4} ({})",
                d.eps, d.eps_reason
            );
            if let Some(m) = settings.sampling_settings.max_eps {
                sampling_reason = format!(
                    "{sampling_reason}; levels coarser than ε {m:.4} split unsampled \
                     (--sampling-max-eps)"
                );
            }
            // What refining every face down to the finest ε would render, for the median cell.
            let mut most: Vec<u64> = cells
                .iter()
                .map(|c| {
                    super::sampling::finest_rectangles(
                        &c.to_f64(),
                        d.eps,
                        settings.sampling_settings.levels,
                    )
                })
                .collect();
            if !most.is_empty() {
                let mid = most.len() / 2;
                let m = *most.select_nth_unstable(mid).1;
                let budget = settings.sampling_settings.budget_points;
                sampling_reason = format!(
                    "{sampling_reason}; up to {m} points per cell (the median cell's faces all \
                     refined to the finest ε){}",
                    if m > budget {
                        format!(", more than the budget of {budget} (--sampling-budget)")
                    } else {
                        String::new()
                    }
                );
            }
            let ss = &settings.sampling_settings;
            sampling_reason = match ss.resolution {
                Some(r) => format!("{sampling_reason}; {r} px per view (--sampling-resolution)"),
                None if ss.fusion == SamplingFusion::Sweep => format!(
                    "{sampling_reason}; {} px per view",
                    SamplingSettings::SWEEP_RESOLUTION
                ),
                None => format!(
                    "{sampling_reason}; pixels per view chosen per cell and level ({} × the \
                     median ray hit distance / ε, {}–{}){}",
                    SamplingSettings::AUTO_PIXELS,
                    SamplingSettings::AUTO_RESOLUTION.0,
                    SamplingSettings::AUTO_RESOLUTION.1,
                    if ss.eps.is_none() {
                        format!(
                            "; a cell whose finest level that rule would render above {t} px \
                             renders at {t} px with its finest ε / √2 instead (about twice the \
                             points)",
                            t = SamplingSettings::TRADE_RESOLUTION
                        )
                    } else {
                        String::new()
                    }
                ),
            };
            if ss.fusion == SamplingFusion::Sweep {
                sampling_reason = format!(
                    "{sampling_reason}; leaves fused by the per-rectangle sweep \
                     (--sampling-fusion sweep, on the CPU)"
                );
            }
            d
        });
        let Pieces {
            ranges: pieces,
            boxes: piece_boxes,
            triangle_ranges: piece_triangle_ranges,
            triangles: piece_triangles,
        } = object_pieces(scene);
        let mut object_parts = vec![Vec::new(); scene.objects.len()];
        for (i, p) in occluders.parts.iter().enumerate() {
            object_parts[p.object as usize].push(i as u32);
        }
        let bounds = scene
            .objects
            .iter()
            .filter(|o| !o.bounds.is_empty())
            .fold(Aabb::EMPTY, |b, o| b.union(&o.bounds))
            .to_f64();
        let rsf_edges = if rsf {
            super::rsf::solid_edges(&occluders)
        } else {
            Vec::new()
        };
        Ok(Prepared {
            sampler_progress: None,
            checkpoints: None,
            occludee_table: None,
            occluder_table: None,
            cullers: pipeline::cullers(settings, rsf, sweep, sampling),
            rsf_edges,
            rsf,
            rsf_reason,
            sampling,
            sampling_reason,
            sampler,
            bounds,
            scene,
            occluders,
            sliceable,
            bvh,
            settings: settings.clone(),
            sweep,
            sweep_reason,
            pieces,
            piece_boxes,
            piece_triangle_ranges,
            piece_triangles,
            object_parts,
        })
    }

    /// With a GPU backend and the sampler on: where the sampler renders, `on the GPU`, or
    /// `on the CPU: ` and why ([`crate::backend::gpu::sampler::GpuSamplerScene::refusal`]).
    pub fn sampler_device(&self, backend: &dyn crate::backend::RasterBackend) -> Option<String> {
        let (g, d) = (backend.as_gpu()?, self.sampler.as_ref()?);
        if let Some(why) = d.settings.gpu_refusal() {
            return Some(format!("on the CPU: {why}"));
        }
        Some(
            match crate::backend::gpu::sampler::GpuSamplerScene::refusal(g, &d.occluders) {
                None => "on the GPU".to_string(),
                Some(why) => format!("on the CPU: {why}"),
            },
        )
    }

    /// The sampler's finest ε from the settings or the occluders (`None` without the
    /// sampler). A cell may sample a finer one where it trades pixels for points
    /// ([`crate::settings::SamplingSettings::cell_finest`]).
    pub fn sampling_eps(&self) -> Option<f64> {
        self.sampler.as_ref().map(|d| d.eps)
    }

    /// The cullers' notes on the bake so far ([`super::Culler::note`]).
    pub fn culler_notes(&self) -> Vec<String> {
        self.cullers.iter().filter_map(|c| c.note()).collect()
    }

    /// The names of the cullers every cell runs, in order.
    pub fn culler_names(&self) -> Vec<&'static str> {
        self.cullers.iter().map(|c| c.name()).collect()
    }

    /// Bakes one cell.
    ///
    /// # Errors
    /// The backend's failure.
    pub fn cell(&self, cell: &Aabb, backend: &dyn RasterBackend) -> Result<CellResult, BakeError> {
        self.cell_observed(cell, backend, &mut super::NoPlanes)
    }

    /// Bakes one cell, handing every rendered plane to `observe` (its job, its Depth Map and
    /// its Hierarchical Depth Map) before its occludees are tested: for dumps and reports.
    /// With `max_pvs_triangles` the result holds the cell's subdivision
    /// ([`CellResult::children`]).
    ///
    /// # Errors
    /// The backend's failure.
    pub fn cell_observed(
        &self,
        cell: &Aabb,
        backend: &dyn RasterBackend,
        observe: &mut dyn PlaneSink,
    ) -> Result<CellResult, BakeError> {
        let min_size = self
            .settings
            .min_cell_size
            .unwrap_or((cell.max - cell.min).max_element() as f64 / MIN_CELL_FRACTION);
        self.cell_tree(cell, None, min_size, backend, observe)
    }

    /// Bakes `cell` (objects in `inherited` start hidden), then, while its PVS holds more
    /// triangles than `max_pvs_triangles` and its longest side exceeds `min_size`, its two
    /// halves along that side, each testing only the objects of this cell's PVS: a half's PVS
    /// is a subset of its parent's, since each of its points is a point of the parent. A half
    /// whose PVS is not at least [`MIN_SPLIT_GAIN`] smaller than its parent's is not split
    /// again (splitting where nothing changes rarely starts to pay one level down).
    fn cell_tree(
        &self,
        cell: &Aabb,
        inherited: Option<(&[bool], u64)>,
        min_size: f64,
        backend: &dyn RasterBackend,
        observe: &mut dyn PlaneSink,
    ) -> Result<CellResult, BakeError> {
        let (mut result, hidden) =
            self.cell_once(cell, inherited.map(|h| h.0), backend, observe)?;
        let Some(limit) = self.settings.max_pvs_triangles else {
            return Ok(result);
        };
        let tris: u64 = (result.visible.iter())
            .map(|&o| self.scene.objects[o as usize].triangles.len() as u64)
            .sum();
        let stalled = inherited
            .is_some_and(|(_, parent)| tris as f64 > (1.0 - MIN_SPLIT_GAIN) * parent as f64);
        if tris <= limit || stalled {
            return Ok(result);
        }
        let Some(halves) = halve(cell, min_size) else {
            return Ok(result);
        };
        for half in halves {
            let child = self.cell_tree(&half, Some((&hidden, tris)), min_size, backend, observe)?;
            result.children.push(super::ChildCell {
                min: half.min.to_array(),
                max: half.max.to_array(),
                result: child,
            });
        }
        Ok(result)
    }

    /// Bakes one cell without subdividing it: its result, and per object whether it is
    /// culled (hidden from every sub-cell).
    fn cell_once(
        &self,
        cell: &Aabb,
        inherited: Option<&[bool]>,
        backend: &dyn RasterBackend,
        observe: &mut dyn PlaneSink,
    ) -> Result<(CellResult, Vec<bool>), BakeError> {
        let start = Instant::now();
        let n = self.scene.objects.len();
        let subcells = match self.settings.subcell {
            Some(size) => split_cell(cell, size),
            None => vec![*cell],
        };
        let mut visible = vec![false; n];
        let mut account = CellAccount::new(self.cullers.len(), n);
        for (k, sub) in subcells.iter().enumerate() {
            let known = (k > 0).then_some(visible.as_slice());
            let hidden = pipeline::run(
                &self.cullers,
                self,
                sub,
                backend,
                known,
                inherited,
                observe,
                &mut account,
            )?;
            for (v, h) in visible.iter_mut().zip(hidden) {
                *v |= !h;
            }
        }
        let stats = account.finish(&visible);
        let hidden: Vec<bool> = visible.iter().map(|v| !v).collect();
        let visible = (0..n as u32)
            .filter(|&o| visible[o as usize] && !self.scene.objects[o as usize].bounds.is_empty())
            .collect();
        Ok((
            CellResult {
                visible,
                // With what earlier runs spent (a cell resumed from a sampler checkpoint).
                ms: start.elapsed().as_secs_f64() * 1e3
                    + stats.iter().map(|s| s.work.resumed_ms).sum::<f64>(),
                planes: stats.iter().map(|s| s.work.planes).sum(),
                occluders_projected: stats.iter().map(|s| s.work.occluders_projected).sum(),
                cullers: stats,
                children: Vec::new(),
            },
            hidden,
        ))
    }
}

/// Without `min_cell_size`, adaptive subdivision stops at cells whose longest side is this
/// fraction of the longest side of the cell given to the bake (at most 3 splits along it).
pub const MIN_CELL_FRACTION: f64 = 8.0;

/// A half of a subdivided cell is split again only when its PVS has at least this share
/// fewer triangles than its parent's.
pub const MIN_SPLIT_GAIN: f64 = 0.02;

/// The two halves of `cell` along its longest side, split at its middle (rounded to `f32`,
/// the halves share the plane exactly); `None` when that side is at most `min_size` or too
/// thin to split in `f32`.
pub fn halve(cell: &Aabb, min_size: f64) -> Option<[Aabb; 2]> {
    let ext = cell.max - cell.min;
    let axis = ext.max_position();
    // A side at the minimum up to f32 rounding (halving a side three times) is at the minimum.
    if (ext[axis] as f64) <= min_size * (1.0 + 1e-6) {
        return None;
    }
    let mid = cell.min[axis] + 0.5 * ext[axis];
    if !(mid > cell.min[axis] && mid < cell.max[axis]) {
        return None;
    }
    let (mut lo, mut hi) = (*cell, *cell);
    lo.max[axis] = mid;
    hi.min[axis] = mid;
    Some([lo, hi])
}

/// The sub-cells of `cell` no larger than `size` along any axis: a regular split, as few per
/// axis as fit.
pub fn split_cell(cell: &Aabb, size: f64) -> Vec<Aabb> {
    let ext = (cell.max - cell.min).as_dvec3();
    let n = (ext / size).ceil().max(glam::DVec3::ONE).as_uvec3();
    let mut out = Vec::with_capacity((n.x * n.y * n.z) as usize);
    let at = |a: usize, k: u32| {
        if k == n[a] {
            cell.max[a]
        } else {
            cell.min[a] + (ext[a] * k as f64 / n[a] as f64) as f32
        }
    };
    for x in 0..n.x {
        for y in 0..n.y {
            for z in 0..n.z {
                out.push(Aabb::new(
                    glam::Vec3::new(at(0, x), at(1, y), at(2, z)),
                    glam::Vec3::new(at(0, x + 1), at(1, y + 1), at(2, z + 1)),
                ));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn occluders_past_the_u32_tables_are_an_error_that_says_what_to_do() {
        assert!(check_occluder_corners(u64::from(u32::MAX)).is_ok());
        let e = check_occluder_corners(u64::from(u32::MAX) + 1).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("4294967296") && msg.contains("--occluders"),
            "{msg}"
        );
    }
}
